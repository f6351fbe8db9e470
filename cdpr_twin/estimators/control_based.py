"""Est. 1, control-based: integrate the commanded platform twist (paper §III-A, eq. 9)."""

from __future__ import annotations

import math
from collections.abc import Mapping

from cdpr_twin.estimators import newton
from cdpr_twin.estimators.base import NO_TWIST, NON_FINITE_INPUT, Estimator, SensorWatch
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.options import NoOptions
from cdpr_twin.types import Measurement, PoseEstimate


class ControlEstimator(Estimator):
    """ᵇT_p(t) = ᵇT_p(t − Δt) · exp(ᵖv_p Δt), with ᵖv_p the twist commanded over the last tick.

    It assumes the robot produced the commanded twist; it reads no sensor.
    """

    name = "control"
    watches = SensorWatch.ENCODERS

    def __init__(self, geometry: CdprGeometry, options: NoOptions | None = None) -> None:
        super().__init__(geometry, options)
        # its compose_exp: compiled (or loaded) now, not at the first update
        newton.warm_up()

    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """Compose the estimate with the exponential of the last commanded twist."""
        m = measurement
        dt = m.time - self._time
        if not math.isfinite(dt) or dt < 0:
            raise ValueError(
                f"control: measurement time {m.time} s precedes the last one "
                f"({self._time} s); feed measurements in time order"
            )
        twist = m.twist_platform
        if twist is None:
            if dt == 0:
                return PoseEstimate(m.time, self._T)
            return self._held(m, NO_TWIST)
        # six Python floats, checked one by one, then one compiled T · exp(ξΔt): a tenth of
        # the time of the NumPy calls on 6-vectors and 4×4 matrices
        v = twist.tolist()
        if not all(map(math.isfinite, v)):
            return self._held(m, NON_FINITE_INPUT)
        vx, vy, vz, wx, wy, wz = v
        self._T = newton.compose_exp(self._T, vx * dt, vy * dt, vz * dt, wx * dt, wy * dt, wz * dt)
        self._time = m.time
        return PoseEstimate(m.time, self._T, flags=watch_flags)
