"""cdpr-twin: a MuJoCo digital twin of the ACROBOT cable-driven parallel robot.

Importing the package changes no global state; :mod:`cdpr_twin.sim` (the only part that imports
MuJoCo) defaults ``MUJOCO_GL`` to ``egl`` before mujoco's first import.
"""

from cdpr_twin import resources

__version__ = "0.1.0"

MODELS_DIR = resources.models_dir()
"""The shipped robots, one directory each (``models/acrobot/scene.xml``…; see
:mod:`cdpr_twin.resources`)."""

SCENARIOS_DIR = resources.scenarios_dir()
"""The shipped scenario files (``scenarios/paper_open_loop.toml``…)."""

DEFAULT_SCENE = MODELS_DIR / "acrobot" / resources.SCENE_FILE
"""The ACROBOT scene: robot, floor, lights and the AprilTag."""
