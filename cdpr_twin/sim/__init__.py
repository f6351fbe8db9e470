"""The simulation layer: the only package of cdpr_twin that imports mujoco.

- :class:`Physics` — the thin core: model/data, winch rates, stepping, swivel/stiffness refresh,
  named ground-truth getters, step hooks;
- :class:`Sensors` — encoders (homed), tension noise, camera rendering and tag detection →
  :class:`~cdpr_twin.types.Measurement`;
- :func:`build_robot` / :class:`Twin` — both assembled from a model file and truth deviations.

Offscreen rendering uses EGL unless the environment already chose a backend: ``MUJOCO_GL`` is
read by mujoco when it is first imported, so its default is set here, before that import.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from cdpr_twin.robot.deviations import DeviationSpec, TruthDeviations
from cdpr_twin.sim.model import ModelError, build_model, cable_count, read_geometry
from cdpr_twin.sim.monitor import Fault, FaultKind, Monitor, MonitorLimits, robot_limits
from cdpr_twin.sim.physics import Physics, SimulationError, StepHook
from cdpr_twin.sim.sensors import NominalRobot, Sensors
from cdpr_twin.sim.twin import Twin, build_robot, nominal_robot
from cdpr_twin.sim.winch import WinchLimitError

__all__ = [
    "DeviationSpec",
    "Fault",
    "FaultKind",
    "ModelError",
    "Monitor",
    "MonitorLimits",
    "NominalRobot",
    "Physics",
    "Sensors",
    "SimulationError",
    "StepHook",
    "TruthDeviations",
    "Twin",
    "WinchLimitError",
    "build_model",
    "build_robot",
    "cable_count",
    "nominal_robot",
    "read_geometry",
    "robot_limits",
]
