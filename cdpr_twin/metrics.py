"""Deviations of estimates from ground truth, and run summaries (paper Fig. 5b, 7b, 8)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from cdpr_twin.estimators.base import PoseEstimate
from cdpr_twin.se3 import pose_distance


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

    def add(
        self,
        estimate: PoseEstimate,
        T_true: np.ndarray,
        distance: tuple[float, float] | None = None,
    ) -> tuple[float, float]:
        """Account one estimate; returns its (translation [m], rotation [rad]) deviation.

        ``distance`` may pass the deviation when it was computed already (vectorised).
        """
        dt, dr = (
            distance if distance is not None else pose_distance(estimate.T_base_platform, T_true)
        )
        if dt > self.max_translation:
            self.max_translation, self.max_translation_time = dt, estimate.time
        if dr > self.max_rotation:
            self.max_rotation, self.max_rotation_time = dr, estimate.time
        self.final_translation, self.final_rotation = dt, dr
        if not estimate.valid:
            self.invalid_updates += 1
        self.flags.update(estimate.flags)
        return dt, dr

    def summary(self) -> dict:
        """JSON-ready summary (metres and degrees)."""
        return {
            "max_translation_m": self.max_translation,
            "max_translation_time_s": self.max_translation_time,
            "max_rotation_deg": float(np.degrees(self.max_rotation)),
            "max_rotation_time_s": self.max_rotation_time,
            "final_translation_m": self.final_translation,
            "final_rotation_deg": float(np.degrees(self.final_rotation)),
            "invalid_updates": self.invalid_updates,
            "flags": dict(sorted(self.flags.items())),
        }


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> dict:
    """JSON-ready distance between two poses (metres and degrees)."""
    dt, dr = pose_distance(T_a, T_b)
    return {"translation_m": dt, "rotation_deg": float(np.degrees(dr))}
