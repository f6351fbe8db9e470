"""cdpr-twin: a MuJoCo digital twin of the ACROBOT cable-driven parallel robot.

Importing the package changes no global state; :mod:`cdpr_twin.sim` (the only part that imports
MuJoCo) defaults ``MUJOCO_GL`` to ``egl`` before mujoco's first import.
"""

from pathlib import Path

__version__ = "0.1.0"

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
"""Model files shipped with the checkout (``models/acrobot/scene.xml``…)."""

DEFAULT_SCENE = MODELS_DIR / "acrobot" / "scene.xml"
"""The ACROBOT scene: robot, floor, lights and the AprilTag."""
