"""The estimators' common interface: reset at a known pose, update from a Measurement.

An estimator sees the nominal geometry, measurements and — when it declares them in
:attr:`Estimator.inputs` — the current estimates of other estimators (a fusing estimator);
never MuJoCo, never ground truth.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.plugins import NoOptions
from cdpr_twin.se3 import check_rigid
from cdpr_twin.types import Measurement, PoseEstimate

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
ILL_CONDITIONED = "ill_conditioned"
"""The cables available form a nearly singular set (Jacobian condition number above the
estimator's ``max_condition``): the estimate is held rather than jump."""
REANCHORED = "reanchored"
"""Image-based: no successive detection pair; the reference restarts at the held estimate."""


NO_INPUTS: Mapping[str, PoseEstimate] = MappingProxyType({})


class Estimator(ABC):
    """A moving-platform pose estimator (paper §III). All start from a known pose.

    Subclasses set ``name`` and ``Options`` (a frozen dataclass whose fields are the
    estimator's scenario options, see :mod:`cdpr_twin.plugins`) and are registered with
    :func:`cdpr_twin.plugins.register`.

    Args:
        geometry: the *nominal* robot geometry the estimator believes in.
        options: an instance of the class's ``Options`` (defaults when ``None``).
    """

    kind: ClassVar[str] = "estimator"
    name: ClassVar[str] = ""
    Options: ClassVar[type] = NoOptions
    needs_camera: ClassVar[bool] = False
    """Whether it reads tag detections (dropped from the passive set when the camera is off)."""
    reports_covariance: ClassVar[bool] = False
    """Whether its estimates carry a covariance (recorded in ``timeseries.csv`` and Rerun)."""

    def __init__(self, geometry: CdprGeometry, options: Any = None) -> None:
        self.geometry = geometry
        self.options = self.Options() if options is None else options
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
    def inputs(self) -> tuple[str, ...]:
        """Names of the estimators whose current estimates :meth:`update` needs (none here)."""
        return ()

    @property
    def T_base_platform(self) -> np.ndarray:
        """The current estimate (4, 4)."""
        return self._T.copy()

    def _check_reset(self) -> None:
        if not self._ready:
            raise RuntimeError(f"{self.name}: call reset(T_base_platform0) before update()")

    def _bad_time(self, m: Measurement) -> PoseEstimate | None:
        """The held, flagged estimate when the measurement's time is NaN or infinite."""
        if np.isfinite(m.time):
            return None
        return PoseEstimate(self._time, self._T, valid=False, flags=frozenset({NON_FINITE_INPUT}))

    def _held(self, m: Measurement, *flags: str, **extra) -> PoseEstimate:
        self._time = m.time
        return PoseEstimate(m.time, self._T, valid=False, flags=frozenset(flags), **extra)

    @abstractmethod
    def update(
        self, measurement: Measurement, inputs: Mapping[str, PoseEstimate] = NO_INPUTS
    ) -> PoseEstimate:
        """Update from one measurement and return the new estimate.

        Args:
            measurement: the sensors' reading.
            inputs: this tick's estimates of the estimators named by :attr:`inputs`.
        """
