"""The six moving-platform pose estimators of the paper (§III), chosen by name.

>>> est = make_estimator("model_elastic_pulley", geometry)
>>> est.reset(T_base_platform0)
>>> estimate = est.update(measurement)
"""

from __future__ import annotations

from typing import Any

from cdpr_twin.estimators.base import Estimator, PoseEstimate
from cdpr_twin.estimators.control import ControlEstimator
from cdpr_twin.estimators.image import ImageEstimator
from cdpr_twin.estimators.model import (
    ElasticModelEstimator,
    ElasticPulleyModelEstimator,
    ModelEstimator,
    PulleyModelEstimator,
    SimpleModelEstimator,
)
from cdpr_twin.geometry import CdprGeometry

ESTIMATORS: dict[str, type[Estimator]] = {
    cls.name: cls
    for cls in (
        ControlEstimator,
        ImageEstimator,
        SimpleModelEstimator,
        ElasticModelEstimator,
        PulleyModelEstimator,
        ElasticPulleyModelEstimator,
    )
}
"""Estimator classes by name, in the paper's order (Est. 1 … Est. 6)."""


def make_estimator(name: str, geometry: CdprGeometry, **options: Any) -> Estimator:
    """Build an estimator by its name (DESIGN §7).

    Args:
        name: one of :data:`ESTIMATORS`.
        geometry: the nominal geometry.
        **options: the estimator's keyword options (e.g. ``reference="first"`` for ``image``,
            ``backend="scipy"`` for ``model_*``).

    Raises:
        ValueError: for an unknown name or option.
    """
    try:
        cls = ESTIMATORS[name]
    except KeyError:
        raise ValueError(
            f"unknown estimator {name!r}; choose one of {', '.join(ESTIMATORS)}"
        ) from None
    try:
        return cls(geometry, **options)
    except TypeError as exc:
        raise ValueError(f"estimator {name!r}: bad options {sorted(options)}: {exc}") from None


__all__ = ["ESTIMATORS", "Estimator", "ModelEstimator", "PoseEstimate", "make_estimator"]
