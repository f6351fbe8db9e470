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

from cdpr_twin.estimators import ESTIMATORS
from cdpr_twin.se3 import matrix_from_quat_wxyz, pose_distances

ESTIMATOR_ORDER = tuple(ESTIMATORS)
"""The six estimators in the paper's order (Est. 1 … Est. 6)."""
MODEL_ESTIMATORS = tuple(n for n in ESTIMATOR_ORDER if n.startswith("model_"))


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
    """How the image-based estimate's noise (and bias) depend on the camera-to-tag distance.

    Noise is the RMS tick-to-tick change of the translational deviation (what the paper sees as
    "highly noisy"); bias is the mean deviation. Both are compared between the rows in the
    nearest and farthest thirds of the detected distance ‖ᶜt_o‖; Spearman's rank correlation is
    between the distance and the size of the tick-to-tick change.
    """
    dist = np.sqrt(sum(ts.columns[f"tag_{k}"] ** 2 for k in "xyz"))
    dev, _ = ts.deviation("image")
    step = np.abs(np.diff(dev))
    d_step = dist[1:]
    ok = np.isfinite(d_step) & np.isfinite(step) & np.isfinite(dist[:-1])
    d_step, step = d_step[ok], step[ok]
    order = np.argsort(d_step)
    third = max(1, len(order) // 3)
    near, far = order[:third], order[-third:]
    rank = lambda v: np.argsort(np.argsort(v)).astype(float)  # noqa: E731
    rho = float(np.corrcoef(rank(d_step), rank(step))[0, 1]) if len(step) > 2 else float("nan")
    ok_dev = np.isfinite(dist) & np.isfinite(dev)
    dd, dv = dist[ok_dev], dev[ok_dev]
    od = np.argsort(dd)
    return {
        "near_distance_m": float(np.median(d_step[near])),
        "far_distance_m": float(np.median(d_step[far])),
        "near_noise_m": float(np.sqrt(np.mean(step[near] ** 2))),
        "far_noise_m": float(np.sqrt(np.mean(step[far] ** 2))),
        "near_mean_deviation_m": float(dv[od[: max(1, len(od) // 3)]].mean()),
        "far_mean_deviation_m": float(dv[od[-max(1, len(od) // 3) :]].mean()),
        "spearman": rho,
    }


def roughness(ts: Timeseries, name: str) -> float:
    """RMS tick-to-tick change of an estimate's translational deviation [m].

    It measures the estimate's noise, as opposed to its bias.
    """
    dev, _ = ts.deviation(name)
    d = np.diff(dev[np.isfinite(dev)])
    return float(np.sqrt(np.mean(d * d))) if len(d) else float("nan")
