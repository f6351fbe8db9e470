"""Est. 1, control-based: integrate the commanded platform twist (paper §III-A, eq. 9)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cdpr_twin.estimators.base import NO_TWIST, NON_FINITE_INPUT, Estimator, SensorWatch
from cdpr_twin.math.se3 import se3_exp
from cdpr_twin.types import Measurement, PoseEstimate


class ControlEstimator(Estimator):
    """ᵇT_p(t) = ᵇT_p(t − Δt) · exp(ᵖv_p Δt), with ᵖv_p the twist commanded over the last tick.

    It assumes the robot produced the commanded twist; it reads no sensor.
    """

    name = "control"
    watches = SensorWatch.ENCODERS

    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """Compose the estimate with the exponential of the last commanded twist."""
        m = measurement
        dt = m.time - self._time
        if not np.isfinite(dt) or dt < 0:
            raise ValueError(
                f"control: measurement time {m.time} s precedes the last one "
                f"({self._time} s); feed measurements in time order"
            )
        twist = m.twist_platform
        if twist is None:
            if dt == 0:
                return PoseEstimate(m.time, self._T)
            return self._held(m, NO_TWIST)
        if not np.all(np.isfinite(twist)):
            return self._held(m, NON_FINITE_INPUT)
        self._T = self._T @ se3_exp(np.asarray(twist) * dt)
        self._time = m.time
        return PoseEstimate(m.time, self._T, flags=watch_flags)
