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
from typing import TYPE_CHECKING

os.environ.setdefault("MUJOCO_GL", "egl")

if TYPE_CHECKING:
    from cdpr_twin.robot.deviations import DeviationSpec, TruthDeviations
    from cdpr_twin.sim.model import ModelError, build_model, cable_count, read_geometry
    from cdpr_twin.sim.monitor import Fault, FaultKind, Monitor, MonitorLimits, robot_limits
    from cdpr_twin.sim.physics import Physics, SimulationError, StepHook
    from cdpr_twin.sim.sensors import NominalRobot, Sensors
    from cdpr_twin.sim.twin import BuiltRobot, Twin, build_robot, nominal_robot
    from cdpr_twin.sim.winch import WinchLimitError

_WHERE = {
    "DeviationSpec": "cdpr_twin.robot.deviations",
    "TruthDeviations": "cdpr_twin.robot.deviations",
    "ModelError": "cdpr_twin.sim.model",
    "build_model": "cdpr_twin.sim.model",
    "cable_count": "cdpr_twin.sim.model",
    "read_geometry": "cdpr_twin.sim.model",
    "Fault": "cdpr_twin.sim.monitor",
    "FaultKind": "cdpr_twin.sim.monitor",
    "Monitor": "cdpr_twin.sim.monitor",
    "MonitorLimits": "cdpr_twin.sim.monitor",
    "robot_limits": "cdpr_twin.sim.monitor",
    "Physics": "cdpr_twin.sim.physics",
    "SimulationError": "cdpr_twin.sim.physics",
    "StepHook": "cdpr_twin.sim.physics",
    "NominalRobot": "cdpr_twin.sim.sensors",
    "Sensors": "cdpr_twin.sim.sensors",
    "Twin": "cdpr_twin.sim.twin",
    "BuiltRobot": "cdpr_twin.sim.twin",
    "build_robot": "cdpr_twin.sim.twin",
    "nominal_robot": "cdpr_twin.sim.twin",
    "WinchLimitError": "cdpr_twin.sim.winch",
}
"""Where each name of this package lives. They are imported when first asked for: importing
one module of the layer that needs no MuJoCo (``cdpr_twin.sim.events``, a scenario's events)
does not start MuJoCo (a second or more)."""


def __getattr__(name: str):
    """The package's names, each imported from its module when first asked for."""
    import importlib

    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


__all__ = [
    "BuiltRobot",
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
