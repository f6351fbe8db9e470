"""Open-loop quintic trajectory velocity controller (paper §IV-B, eq. 26-30)."""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Literal

import numpy as np

from cdpr_twin.controllers.base import Controller
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import jacobian
from cdpr_twin.math.se3 import so3_exp, so3_log, transform, vector_from_pose
from cdpr_twin.math.workspace import infeasible_reason, is_feasible
from cdpr_twin.options import OptionError, option
from cdpr_twin.types import Command, Measurement, PoseEstimate, Status

MIN_PERIODS = 5
"""The fewest control periods a segment may last (see :meth:`OpenLoopController.check_period`)."""
MAX_WAYPOINTS = 1000
"""The most waypoints a plan may pass through. Each quintic segment starts and ends at rest
(eq. 26), so 1 000 waypoints are 1 000 stops, far beyond any task of this kind (the paper's has
3); and before a run each waypoint costs one linear program (its wrench feasibility, ~2 ms),
which this bound keeps to about 2 s."""
_WHY = " (each segment stops at its waypoint: a path, not a trajectory's samples)"


def quintic(tau: float) -> tuple[float, float]:
    """s(τ) and ds/dτ of eq. 26 with s(0) = ṡ(0) = s̈(0) = 0, s(1) = 1, ṡ(1) = s̈(1) = 0.

    Args:
        tau: normalised time in [0, 1] (clipped).

    Returns:
        ``(s, ds/dτ)``.
    """
    x = min(max(tau, 0.0), 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x * x), 30.0 * x * x * (1.0 - x) ** 2


class Segment:
    """One straight-line quintic segment p_s → p_f over a duration (eq. 26-29).

    Args:
        T_start: (4, 4) start pose p_s.
        T_end: (4, 4) end pose p_f.
        duration: segment duration [s] (> 0).
    """

    def __init__(self, T_start: np.ndarray, T_end: np.ndarray, duration: float) -> None:
        if not duration > 0:
            raise ValueError(f"segment duration must be > 0 s, got {duration}")
        self.T_start, self.T_end, self.duration = T_start, T_end, float(duration)
        self.dt = T_end[:3, 3] - T_start[:3, 3]
        self.theta_u = so3_log(T_start[:3, :3].T @ T_end[:3, :3])  # θ_p u_p of ᵖˢR_pf
        # the twist per unit ṡ, [Δt, R_s θu] (eq. 27b, 29): one product a sample
        self._twist_unit = np.concatenate([self.dt, T_start[:3, :3] @ self.theta_u])

    def pose(self, t: float) -> np.ndarray:
        """Planned pose at time t from the segment start (eq. 27a, 28). Returns (4, 4)."""
        s, _ = quintic(t / self.duration)
        R = self.T_start[:3, :3] @ so3_exp(self.theta_u * s)
        return transform(R, self.T_start[:3, 3] + self.dt * s)

    def twist_base(self, t: float) -> np.ndarray:
        """Planned twist ᵇv_p = [v, ω] in F_b at time t (eq. 27b, 29). Returns (6,).

        ω = R_s θu ṡ: θu is expressed in F_ps, so it is rotated into F_b (the paper's eq. 29
        writes θu ṡ, which is the same only when R_s = I).
        """
        _, ds = quintic(t / self.duration)
        return self._twist_unit * (ds / self.duration)


@dataclass(frozen=True)
class OpenLoopOptions:
    """The open-loop task.

    Attributes:
        waypoints: (k,) of (4, 4) poses the trajectory passes through after the start pose
            (file: a list of ``[x, y, z, rx, ry, rz]`` in m and degrees).
        durations: (k,) segment durations [s].
        jacobian_model: cable model of Â (``"straight"``: eq. 6, as in the paper).
    """

    waypoints: tuple[np.ndarray, ...] = option(
        pose=True, max_items=MAX_WAYPOINTS, max_items_why=_WHY
    )
    durations: tuple[float, ...] = option(unit="s", max_items=MAX_WAYPOINTS, max_items_why=_WHY)
    jacobian_model: Literal["straight", "pulley"] = option("straight")

    def __post_init__(self) -> None:
        n = len(self.waypoints)
        if n == 0:
            raise OptionError(
                "waypoints", "must be a non-empty list of poses [x, y, z, rx, ry, rz]"
            )
        if n > MAX_WAYPOINTS:
            raise OptionError(
                "waypoints", f"must list at most {MAX_WAYPOINTS} poses{_WHY}, got {n}"
            )
        if len(self.durations) != n or not all(np.isfinite(d) and d > 0 for d in self.durations):
            raise OptionError(
                "durations",
                f"must list {n} segment durations > 0 s (one per waypoint), got "
                f"{list(self.durations)!r}",
            )
        if self.jacobian_model not in ("straight", "pulley"):
            raise OptionError(
                "jacobian_model", f"must be 'straight' or 'pulley', got {self.jacobian_model!r}"
            )


class OpenLoopController(Controller):
    """Follow straight quintic segments through waypoints with l̇ = Â ᵇv_p (eq. 30).

    Â is evaluated at the *planned* pose; the estimate is not used. Over each control period
    the twist and Jacobian are sampled at the period's midpoint (the natural discretisation
    of eq. 30 under a zero-order hold).

    Args:
        geometry: nominal geometry.
        options: :class:`OpenLoopOptions`.
    """

    name = "open_loop"
    Options = OpenLoopOptions
    timeout_status = Status.COMPLETED

    def __init__(self, geometry: CdprGeometry, options: OpenLoopOptions) -> None:
        super().__init__(geometry, options)
        self.waypoints = [np.asarray(w, dtype=float) for w in options.waypoints]
        self.durations = [float(d) for d in options.durations]
        self.check()
        self.jacobian_model = options.jacobian_model
        self.segments: list[Segment] = []
        self._starts: list[float] = []
        self._total = self.total_duration

    def check(self) -> None:
        """Every waypoint inside the frame and wrench-feasible (:mod:`cdpr_twin.math.workspace`).

        Wrench-feasible: holdable with tensions within the robot's limits
        (``cable_tension_range`` in the model; 2…75 N without it).

        Raises:
            OptionError: naming the waypoint (``waypoints[i]``, from 0).
        """
        for i, w in enumerate(self.waypoints):
            where = f"{vector_from_pose(w).round(4).tolist()}"
            try:
                self.geometry.check_pose_inside(w, "waypoint")
            except ValueError as exc:
                raise OptionError(
                    f"waypoints[{i}]", f"{where} is outside the frame: {exc}"
                ) from None
            if not is_feasible(self.geometry, w):
                raise OptionError(f"waypoints[{i}]", f"{where} {infeasible_reason(self.geometry)}")

    def check_period(self, period: float) -> None:
        """Each segment lasts at least :data:`MIN_PERIODS` control periods.

        The twist is sampled once per period, at its midpoint (eq. 30): over n periods that
        midpoint rule pays out a quintic segment's motion × (1 + e(n)), e = 87.5 % for n = 1,
        5.5 % for 2, 1.1 % for 3, 0.34 % for 4, 0.14 % for 5; a shorter segment would be skipped.

        Raises:
            OptionError: naming the segment (``durations[i]``, from 0).
        """
        for i, d in enumerate(self.durations):
            if d < MIN_PERIODS * period * (1 - 1e-9):
                raise OptionError(
                    f"durations[{i}]",
                    f"{d:g} s is shorter than {MIN_PERIODS} control periods ({period:g} s each):"
                    " the twist is sampled once per period, at its midpoint, which over fewer "
                    "periods pays the segment's motion out wrong by more than 0.14 % (87.5 % "
                    f"over one period, skipped below it); make it ≥ {MIN_PERIODS * period:g} s",
                )

    @property
    def total_duration(self) -> float:
        """Duration of the whole trajectory [s]."""
        return float(sum(self.durations))

    def reset(self, T_base_platform0: np.ndarray) -> None:
        """Plan the segments from the start pose through the waypoints."""
        poses = [np.asarray(T_base_platform0, dtype=float), *self.waypoints]
        self.segments = [
            Segment(a, b, d) for a, b, d in zip(poses[:-1], poses[1:], self.durations, strict=True)
        ]
        self._starts = np.concatenate([[0.0], np.cumsum(self.durations)]).tolist()

    def _locate(self, t: float) -> tuple[Segment, float]:
        # (a list's bisect: NumPy's searchsorted costs more than the search on a scalar)
        k = bisect.bisect_right(self._starts, t) - 1
        k = min(max(k, 0), len(self.segments) - 1)
        return self.segments[k], t - self._starts[k]

    def planned_pose(self, t: float) -> np.ndarray:
        """Planned pose at time t (the last waypoint after the end)."""
        seg, tau = self._locate(min(t, self._total))
        return seg.pose(tau)

    def planned_twist_base(self, t: float) -> np.ndarray:
        """Planned twist ᵇv_p at time t (zero outside the trajectory)."""
        if t < 0 or t > self._total:
            return np.zeros(6)
        seg, tau = self._locate(t)
        return seg.twist_base(tau)

    def command(
        self,
        t: float,
        period: float,
        estimate: PoseEstimate | None,
        measurement: Measurement | None,
    ) -> Command:
        """l̇ = Â(planned pose) ᵇv_p at the midpoint of [t, t + period] (eq. 30).

        The plan reads no sensor: ``estimate`` and ``measurement`` may be ``None``.
        """
        if not self.segments:
            raise RuntimeError("open_loop: call reset(T_base_platform0) before command()")
        mid = t + 0.5 * period
        # planned_pose(mid) and planned_twist_base(mid) from one look-up of the segment
        seg, tau = self._locate(min(mid, self._total))
        T = seg.pose(tau)
        outside = mid < 0 or mid > self._total
        twist_base = np.zeros(6) if outside else seg.twist_base(tau)
        rates = jacobian(self.geometry, T, "base", self.jacobian_model) @ twist_base
        # rows [v, ω] times R: [Rᵀv, Rᵀω] in one product
        twist_platform = (twist_base.reshape(2, 3) @ T[:3, :3]).ravel()
        done = t + period >= self._total - 1e-9
        return Command(
            rates, twist_platform, done=done, status=Status.DONE if done else Status.TRACKING
        )

    def planned_rates(self, T_start: np.ndarray, period: float, duration: float) -> np.ndarray:
        """The winch rates :meth:`command` will give at each tick of a run (it reads no sensor).

        Plans from ``T_start`` (:meth:`reset`), as a run does.

        Args:
            T_start: (4, 4) the start pose.
            period: the control period [s].
            duration: the run's duration [s] (its ticks are rounded as the run rounds them).

        Returns:
            (ticks, m) rates [m/s], up to the tick whose command ends the plan.
        """
        self.reset(T_start)
        rows = []
        for k in range(round(duration / period)):
            command = self.command(k * period, period, None, None)
            rows.append(command.cable_rates)
            if command.done:
                break
        return np.array(rows).reshape(len(rows), self.geometry.n_cables)

    def goal_pose(self, T_base_tag: np.ndarray | None) -> np.ndarray:
        """The last waypoint."""
        return self.waypoints[-1]

    def checkpoints(self, duration: float) -> list[tuple[float, np.ndarray]]:
        """The end of each segment reached within ``duration``, with its waypoint."""
        ends = np.cumsum(self.durations)
        return [
            (float(t), w) for t, w in zip(ends, self.waypoints, strict=True) if t <= duration + 1e-9
        ]
