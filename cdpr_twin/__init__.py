"""cdpr-twin: a MuJoCo digital twin of the ACROBOT cable-driven parallel robot."""

import os
from pathlib import Path

# Offscreen rendering through EGL unless the user chose a backend. MuJoCo reads this when it is
# first imported, so it is set here, at the top of the package, before cdpr_twin.sim imports it.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
"""Model files shipped with the checkout (``models/acrobot/scene.xml``…)."""

DEFAULT_SCENE = MODELS_DIR / "acrobot" / "scene.xml"
"""The ACROBOT scene: robot, floor, lights and the AprilTag."""
