"""The six moving-platform pose estimators of the paper (§III) and ``fused`` (Est. 7), by name.

>>> est = make_estimator("model_elastic_pulley", geometry)
>>> est.reset(T_base_platform0)
>>> estimate = est.update(measurement)

Each registers itself in :mod:`cdpr_twin.plugins`; more can be registered from outside the
package (a scenario file's ``plugins`` list imports them).
"""

from __future__ import annotations

from typing import Any

from cdpr_twin import plugins
from cdpr_twin.estimators.base import Estimator
from cdpr_twin.estimators.control import ControlEstimator
from cdpr_twin.estimators.image import ImageEstimator
from cdpr_twin.estimators.model import (
    ElasticModelEstimator,
    ElasticPulleyModelEstimator,
    ModelEstimator,
    PulleyModelEstimator,
    SimpleModelEstimator,
)

# isort: split
# Est. 7 registers after the paper's six, so listings keep the paper's order first.
from cdpr_twin.estimators.fused import FusedEstimator
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.types import PoseEstimate

PAPER_ESTIMATORS = tuple(
    cls.name
    for cls in (
        ControlEstimator,
        ImageEstimator,
        SimpleModelEstimator,
        ElasticModelEstimator,
        PulleyModelEstimator,
        ElasticPulleyModelEstimator,
    )
)
"""The paper's six estimators, in its order (Est. 1 … Est. 6)."""
EXTRA_ESTIMATORS = (FusedEstimator.name,)
"""Estimators beyond the paper: Est. 7, the fused filter (issue 11)."""

# Est. 7 (issue 10), registered after the paper's six so that their order stays the paper's
from cdpr_twin.estimators import catenary as _catenary  # noqa: E402, F401


def make_estimator(name: str, geometry: CdprGeometry, **options: Any) -> Estimator:
    """Build a registered estimator by name (DESIGN §7).

    Args:
        name: a registered estimator name (:func:`cdpr_twin.plugins.names`).
        geometry: the nominal geometry.
        **options: fields of the estimator's ``Options`` (e.g. ``reference="first"`` for
            ``image``, ``backend="scipy"`` for ``model_*``).

    Raises:
        ValueError: for an unknown name or option.
    """
    return plugins.build("estimator", name, geometry, **options)


__all__ = [
    "EXTRA_ESTIMATORS",
    "PAPER_ESTIMATORS",
    "Estimator",
    "ModelEstimator",
    "PoseEstimate",
    "make_estimator",
]
