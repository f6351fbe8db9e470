"""Deviations of estimates from ground truth, checkpoints and run summaries (Fig. 5b, 7b, 8).

Ground truth enters here and in the recorders only: it is passed next to the estimates, never
inside what estimators and controllers see.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdpr_twin.math.se3 import pose_distance, pose_error, vector_from_pose
from cdpr_twin.types import PoseEstimate, TickRecord

NON_FINITE_ESTIMATE = "non_finite_estimate"
"""The flag counted for an estimate whose pose is not finite (no deviation is measured)."""


def sample_std(values) -> float:
    """The sample standard deviation (n − 1 in the denominator) of a spread over repetitions.

    Args:
        values: (n,) values.

    Returns:
        The std, 0.0 for fewer than two values (no spread measured).
    """
    x = np.asarray(values, dtype=float)
    return float(x.std(ddof=1)) if x.size > 1 else 0.0


_NO_DEVIATION = dict.fromkeys(
    (
        "max_translation_m",
        "max_translation_time_s",
        "max_rotation_deg",
        "max_rotation_time_s",
        "rms_translation_m",
        "rms_rotation_deg",
    ),
    math.nan,
)


@dataclass
class DeviationTrack:
    """Running translational/rotational deviation of one estimator from ground truth."""

    max_translation: float = 0.0
    max_translation_time: float = 0.0
    max_rotation: float = 0.0
    max_rotation_time: float = 0.0
    final_translation: float = float("nan")
    final_rotation: float = float("nan")
    invalid_updates: int = 0
    flags: Counter = field(default_factory=Counter)
    sum_sq_translation: float = 0.0
    sum_sq_rotation: float = 0.0
    count: int = 0

    def add(self, estimate: PoseEstimate, distance: tuple[float, float]) -> None:
        """Account one estimate and its (translation [m], rotation [rad]) deviation.

        A non-finite estimate (a broken estimator's NaN pose) has no deviation to measure: it
        counts as an invalid update, raises the flag :data:`NON_FINITE_ESTIMATE` and leaves the
        final deviation NaN; the max and RMS are over the finite estimates.
        """
        dt, dr = distance
        if not (math.isfinite(dt) and math.isfinite(dr)):
            self.invalid_updates += 1
            self.flags.update({*estimate.flags, NON_FINITE_ESTIMATE})
            self.final_translation = self.final_rotation = math.nan
            return
        if dt > self.max_translation:
            self.max_translation, self.max_translation_time = dt, estimate.time
        if dr > self.max_rotation:
            self.max_rotation, self.max_rotation_time = dr, estimate.time
        self.final_translation, self.final_rotation = dt, dr
        self.sum_sq_translation += dt * dt
        self.sum_sq_rotation += dr * dr
        self.count += 1
        if not estimate.valid:
            self.invalid_updates += 1
        # most estimates carry no flag: Counter.update costs a type check even on nothing
        for flag in estimate.flags:
            self.flags[flag] += 1

    def summary(self) -> dict:
        """JSON-ready summary (metres and degrees).

        Without a single finite estimate the max and RMS deviations are NaN (``null`` in JSON):
        an estimator that never estimated has no deviation to report, least of all zero.
        """
        summary = {
            "max_translation_m": self.max_translation,
            "max_translation_time_s": self.max_translation_time,
            "max_rotation_deg": float(np.degrees(self.max_rotation)),
            "max_rotation_time_s": self.max_rotation_time,
            "final_translation_m": self.final_translation,
            "final_rotation_deg": float(np.degrees(self.final_rotation)),
            "invalid_updates": self.invalid_updates,
            "flags": dict(sorted(self.flags.items())),
            "rms_translation_m": float(np.sqrt(self.sum_sq_translation / max(self.count, 1))),
            "rms_rotation_deg": float(
                np.degrees(np.sqrt(self.sum_sq_rotation / max(self.count, 1)))
            ),
        }
        return summary if self.count else {**summary, **_NO_DEVIATION}


class RunMetrics:
    """Every estimator's deviation from ground truth, tick by tick, and the checkpoints.

    The deviations are accounted ``batch`` ticks at a time (one
    :func:`~cdpr_twin.math.se3.pose_distance` over them all), and the rest when
    :meth:`estimators` is asked for.

    Args:
        names: the estimators, in recording order.
        checkpoints: (time [s], pose) pairs at which to record where the platform is.
        period: the control period [s] (a checkpoint matches the tick within half of it).
        batch: ticks whose deviations are computed together.
    """

    def __init__(
        self,
        names: tuple[str, ...],
        checkpoints: list[tuple[float, np.ndarray]],
        period: float,
        batch: int = 25,
    ) -> None:
        self.tracks = {name: DeviationTrack() for name in names}
        self.checkpoints, self.period, self.batch = checkpoints, period, batch
        self.segment_ends: list[dict] = []
        self._pending: list[tuple[dict[str, PoseEstimate], np.ndarray]] = []

    def add(self, tick: TickRecord) -> None:
        """Take one tick: its deviations are accounted with its batch's, a checkpoint now."""
        self._pending.append((tick.estimates, tick.T_base_platform))
        if len(self._pending) >= self.batch:
            self._account()
        for t_c, waypoint in self.checkpoints:
            if abs(tick.time - t_c) < 0.5 * self.period:
                self.segment_ends.append(
                    _segment_end(tick.time, waypoint, tick.T_base_platform, tick.estimates)
                )

    def _account(self) -> None:
        """Add the pending ticks' deviations to the tracks, in time order."""
        pending, self._pending = self._pending, []
        names = tuple(self.tracks)
        if not (pending and names):
            return
        T_est = np.array(
            [[estimates[n].T_base_platform for n in names] for estimates, _ in pending]
        )
        T_true = np.array([T for _, T in pending])[:, None]
        dts, drs = pose_distance(T_est, T_true)  # (ticks, estimators) each
        tracks = tuple(self.tracks.values())
        for (estimates, _), dt_row, dr_row in zip(pending, dts.tolist(), drs.tolist(), strict=True):
            for name, track, dt, dr in zip(names, tracks, dt_row, dr_row, strict=True):
                track.add(estimates[name], (dt, dr))

    def estimators(self) -> dict[str, dict]:
        """Each estimator's summary (max/final deviations, invalid updates, flags)."""
        self._account()
        return {name: t.summary() for name, t in self.tracks.items()}


def _segment_end(
    time: float, waypoint: np.ndarray, T_true: np.ndarray, estimates: dict[str, PoseEstimate]
) -> dict:
    return {
        "time_s": time,
        "waypoint": vector_from_pose(waypoint).tolist(),
        "truth_vs_waypoint": pose_error(T_true, waypoint),
        "true_pose": vector_from_pose(T_true).tolist(),
        "estimates_vs_truth": {
            n: pose_error(e.T_base_platform, T_true) for n, e in estimates.items()
        },
        "estimates_vs_plan": {
            n: pose_error(e.T_base_platform, waypoint) for n, e in estimates.items()
        },
    }


def run_summary(
    scenario: Any,
    status: str,
    metrics: RunMetrics,
    end: dict[str, Any],
    goal: np.ndarray | None,
    extra: dict[str, Any],
) -> dict:
    """The content of ``summary.json``.

    Args:
        scenario: the :class:`~cdpr_twin.scenario.loading.Scenario` that ran.
        status: how it ended.
        metrics: the run's deviations and checkpoints.
        end: ground truth at the end: ``time`` [s], ``T_base_platform`` (4, 4), ``tensions`` (m,).
        goal: (4, 4) the controller's goal pose, or ``None``.
        extra: the controller's own summary fields.

    The last key, ``software``, names what computed the run: the package's, MuJoCo's, NumPy's
    and Python's versions and the git commit (:func:`cdpr_twin.provenance.software`).
    """
    from cdpr_twin.provenance import software

    s, T_end = scenario, end["T_base_platform"]
    return {
        "scenario": s.name,
        "source": str(s.source),
        "nominal_model": None if s.model.nominal is None else str(s.model.nominal),
        "status": status,
        "controller": s.controller.type,
        "in_loop": s.estimators.in_loop,
        "estimator_names": list(s.estimators.names),
        "seed": s.seed,
        "truth_seed": s.truth.seed,
        "camera": s.sensors.camera,
        "overrides": dict(s.overrides),
        "timestep_s": s.model.timestep,
        "control_rate_hz": s.model.control_rate,
        "simulated_time_s": end["time"],
        "final_pose": vector_from_pose(T_end).tolist(),
        "goal_pose": None if goal is None else vector_from_pose(goal).tolist(),
        "final_error_vs_goal": None if goal is None else pose_error(T_end, goal),
        "estimators": metrics.estimators(),
        "segment_ends": metrics.segment_ends,
        "final_tensions_n": end["tensions"].tolist(),
        **extra,
        "software": software(),
    }
