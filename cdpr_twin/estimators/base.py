"""The estimators' common interface: reset at a known pose, update from a Measurement."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.measurement import Measurement
from cdpr_twin.se3 import check_rigid

TAG_LOST = "tag_lost"
"""No tag detection in this measurement: the estimate is held."""
NO_CAMERA = "no_camera"
"""The measurement carries no image: the image-based estimate is held."""
FEW_TAUT_CABLES = "fewer_than_six_taut_cables"
"""Fewer than six cables read a tension above the taut threshold: the estimate is held."""
NON_FINITE_INPUT = "non_finite_input"
"""A length, tension or twist in the measurement is NaN or infinite: the estimate is held."""
NO_TWIST = "no_twist"
"""Time advanced but no commanded twist was recorded: the control-based estimate is held."""
NOT_CONVERGED = "not_converged"
"""The least-squares solve did not converge: the estimate is held."""
REANCHORED = "reanchored"
"""Image-based: no successive detection pair; the reference restarts at the held estimate."""


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """One estimate of the platform pose.

    Attributes:
        time: time of the measurement it comes from [s].
        T_base_platform: (4, 4) estimated pose (the last valid one when ``valid`` is False).
        valid: whether this update produced a new estimate from its inputs.
        flags: why not, or what is special (the module constants of
            :mod:`cdpr_twin.estimators.base`).
        cables: indices (from 0) of the cables used, for model-based estimators.
        residual: largest |model length − measured length| over the cables used [m].
        iterations: solver iterations.
    """

    time: float
    T_base_platform: np.ndarray
    valid: bool = True
    flags: frozenset[str] = field(default_factory=frozenset)
    cables: tuple[int, ...] = ()
    residual: float = 0.0
    iterations: int = 0

    def __post_init__(self) -> None:
        T = np.array(self.T_base_platform, dtype=float)
        T.flags.writeable = False
        object.__setattr__(self, "T_base_platform", T)
        if not isinstance(self.flags, frozenset):
            object.__setattr__(self, "flags", frozenset(self.flags))


class Estimator(ABC):
    """A moving-platform pose estimator (paper §III). All start from a known pose.

    Args:
        geometry: the *nominal* robot geometry the estimator believes in.
    """

    name: str = ""

    def __init__(self, geometry: CdprGeometry) -> None:
        self.geometry = geometry
        self._T = np.full((4, 4), np.nan)
        self._time = np.nan
        self._ready = False

    def reset(self, T_base_platform0: np.ndarray, time: float = 0.0) -> None:
        """Start from a known platform pose ᵇp_p0 at a given time.

        Args:
            T_base_platform0: (4, 4) initial pose.
            time: time of that pose [s].
        """
        T = check_rigid(T_base_platform0, f"{self.name}: initial pose")
        self._T = T.copy()
        self._time = float(time)
        self._ready = True

    @property
    def T_base_platform(self) -> np.ndarray:
        """The current estimate (4, 4)."""
        return self._T.copy()

    def _check_reset(self) -> None:
        if not self._ready:
            raise RuntimeError(f"{self.name}: call reset(T_base_platform0) before update()")

    def _held(self, m: Measurement, *flags: str, **extra) -> PoseEstimate:
        self._time = m.time
        return PoseEstimate(m.time, self._T, valid=False, flags=frozenset(flags), **extra)

    @abstractmethod
    def update(self, measurement: Measurement) -> PoseEstimate:
        """Update from one measurement and return the new estimate."""
