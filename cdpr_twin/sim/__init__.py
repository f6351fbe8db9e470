"""The simulation layer: the only package of cdpr_twin that imports mujoco.

Offscreen rendering uses EGL unless the environment already chose a backend (``MUJOCO_GL``,
set by ``cdpr_twin/__init__.py`` before mujoco is first imported).
"""

from cdpr_twin.deviations import DeviationSpec, TruthDeviations
from cdpr_twin.sim.model import ModelError, build_model, read_geometry
from cdpr_twin.sim.twin import SimulationError, Twin

__all__ = [
    "DeviationSpec",
    "ModelError",
    "SimulationError",
    "TruthDeviations",
    "Twin",
    "build_model",
    "read_geometry",
]
