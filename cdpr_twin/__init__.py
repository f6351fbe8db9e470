"""cdpr-twin: a MuJoCo digital twin of the ACROBOT cable-driven parallel robot.

The entry points a user needs are importable from the package itself::

    from cdpr_twin import Twin, load_scenario, run

Each is imported from its module when first asked for, so importing the package changes no
global state and starts no MuJoCo; :mod:`cdpr_twin.sim` (the only part that imports MuJoCo)
defaults ``MUJOCO_GL`` to ``egl`` before mujoco's first import.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cdpr_twin import resources

if TYPE_CHECKING:
    from cdpr_twin.plugins import register
    from cdpr_twin.robot.deviations import DeviationSpec
    from cdpr_twin.run.runner import RunResult, run
    from cdpr_twin.scenario.loading import Scenario, ScenarioError, load_scenario
    from cdpr_twin.sim.twin import Twin

__version__ = "0.1.0"

MODELS_DIR = resources.models_dir()
"""The shipped robots, one directory each (``models/acrobot/scene.xml``…; see
:mod:`cdpr_twin.resources`)."""

SCENARIOS_DIR = resources.scenarios_dir()
"""The shipped scenario files (``scenarios/paper_open_loop.toml``…)."""

DEFAULT_SCENE = MODELS_DIR / "acrobot" / resources.SCENE_FILE
"""The ACROBOT scene: robot, floor, lights and the AprilTag."""

_WHERE = {
    "DeviationSpec": "cdpr_twin.robot.deviations",
    "RunResult": "cdpr_twin.run.runner",
    "Scenario": "cdpr_twin.scenario.loading",
    "ScenarioError": "cdpr_twin.scenario.loading",
    "Twin": "cdpr_twin.sim.twin",
    "load_scenario": "cdpr_twin.scenario.loading",
    "register": "cdpr_twin.plugins",
}
"""Where each entry point lives; imported when first asked for. (``run`` is the package
:mod:`cdpr_twin.run`, which runs a scenario when called.)"""


def __getattr__(name: str) -> object:
    """The package's entry points, each imported from its module when first asked for."""
    import importlib

    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


__all__ = [
    "DEFAULT_SCENE",
    "MODELS_DIR",
    "SCENARIOS_DIR",
    "DeviationSpec",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "Twin",
    "__version__",
    "load_scenario",
    "register",
    "run",
]
