"""Load run outputs (``timeseries.csv``, ``summary.json``) and compute the paper's quantities.

Everything here reads files only, so a report can be recomputed from a ``reproduce`` output
directory (or any run directory) without rerunning anything.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_twin.metrics import pose_distances
from cdpr_twin.se3 import matrix_from_quat_wxyz

ESTIMATOR_ORDER = (
    "control",
    "image",
    "model_simple",
    "model_elastic",
    "model_pulley",
    "model_elastic_pulley",
)
MODEL_ESTIMATORS = ESTIMATOR_ORDER[2:]


@dataclass(frozen=True, eq=False)
class Timeseries:
    """One run's ``timeseries.csv`` as arrays.

    Attributes:
        columns: float columns by name (NaN where the file is empty), each (n,).
        status: (n,) controller status per row.
    """

    columns: dict[str, np.ndarray]
    status: np.ndarray

    @property
    def t(self) -> np.ndarray:
        """Time [s], (n,)."""
        return self.columns["t"]

    def has(self, prefix: str) -> bool:
        """Whether poses named ``prefix`` (e.g. an estimator) are in the file."""
        return f"{prefix}_x" in self.columns

    def poses(self, prefix: str) -> np.ndarray:
        """Poses ``<prefix>_{x,y,z,qw,qx,qy,qz}`` as (n, 4, 4) transforms (NaN rows stay NaN)."""
        c = self.columns
        q = np.stack([c[f"{prefix}_q{k}"] for k in "wxyz"], axis=1)
        T = np.tile(np.eye(4), (len(q), 1, 1))
        T[:, :3, 3] = np.stack([c[f"{prefix}_{k}"] for k in "xyz"], axis=1)
        ok = np.all(np.isfinite(q), axis=1)
        T[ok, :3, :3] = [matrix_from_quat_wxyz(v) for v in q[ok]]
        T[~ok] = np.nan
        return T

    def deviation(self, prefix: str, reference: str = "true") -> tuple[np.ndarray, np.ndarray]:
        """Translational [m] and rotational [rad] distance of ``prefix`` poses to ``reference``."""
        return pose_distances(self.poses(prefix), self.poses(reference))

    def matrix(self, prefix: str, n: int = 8) -> np.ndarray:
        """Columns ``<prefix>_1 … <prefix>_n`` as (rows, n)."""
        return np.stack([self.columns[f"{prefix}_{i + 1}"] for i in range(n)], axis=1)


def load_timeseries(path: str | Path) -> Timeseries:
    """Read a run's ``timeseries.csv``."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    status = np.array([r[-1] for r in body])
    columns = {}
    for j, name in enumerate(header[:-1]):
        columns[name] = np.array([float(r[j]) if r[j] else np.nan for r in body])
    return Timeseries(columns, status)


def load_summary(path: str | Path) -> dict:
    """Read a run's ``summary.json``."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def value_at(ts: Timeseries, t: float, values: np.ndarray) -> float:
    """The value of a per-row array at the row whose time is nearest to t."""
    return float(values[int(np.argmin(np.abs(ts.t - t)))])


def image_noise_vs_distance(ts: Timeseries) -> dict:
    """How the image-based estimate's deviation grows with the camera-to-tag distance.

    Uses the detected tag distance ‖ᶜt_o‖ of each row; compares the mean deviation of the rows
    in the farthest and nearest thirds, and Spearman's rank correlation.
    """
    dist = np.sqrt(sum(ts.columns[f"tag_{k}"] ** 2 for k in "xyz"))
    dev, _ = ts.deviation("image")
    ok = np.isfinite(dist) & np.isfinite(dev)
    dist, dev = dist[ok], dev[ok]
    order = np.argsort(dist)
    third = max(1, len(order) // 3)
    near, far = dev[order[:third]], dev[order[-third:]]
    rank = lambda v: np.argsort(np.argsort(v)).astype(float)  # noqa: E731
    rho = float(np.corrcoef(rank(dist), rank(dev))[0, 1]) if len(dist) > 2 else float("nan")
    return {
        "near_distance_m": float(np.median(dist[order[:third]])),
        "far_distance_m": float(np.median(dist[order[-third:]])),
        "near_mean_deviation_m": float(near.mean()),
        "far_mean_deviation_m": float(far.mean()),
        "spearman": rho,
    }


def roughness(ts: Timeseries, name: str) -> float:
    """RMS tick-to-tick change of an estimate's translational deviation [m].

    It measures the estimate's noise, as opposed to its bias.
    """
    dev, _ = ts.deviation(name)
    d = np.diff(dev[np.isfinite(dev)])
    return float(np.sqrt(np.mean(d * d))) if len(d) else float("nan")
