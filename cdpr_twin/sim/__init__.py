"""The simulation layer: the only package of cdpr_twin that imports mujoco.

Offscreen rendering uses EGL unless the environment already chose a backend (``MUJOCO_GL``).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from cdpr_twin.sim.model import (
    DeviationSpec,
    ModelError,
    TruthDeviations,
    build_model,
    read_geometry,
)
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
