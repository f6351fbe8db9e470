"""The paper's quantities, computed from run outputs (``timeseries.csv``, ``summary.json``).

The file format of ``timeseries.csv`` is :mod:`cdpr_twin.recording.timeseries`'s (re-exported here:
:class:`Timeseries`, :func:`load_timeseries`). Which estimators a run has comes from the run
itself, never from a list here. Everything here reads files only, so a report can be
recomputed from a ``reproduce`` output directory (or any run directory) without rerunning.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from cdpr_twin.estimators import PAPER_ESTIMATORS  # display order and colours only
from cdpr_twin.recording.timeseries import Timeseries, load_timeseries

__all__ = [
    "PAPER_ESTIMATORS",
    "Timeseries",
    "image_noise_vs_distance",
    "load_summary",
    "load_timeseries",
    "model_estimators",
    "ordered_estimators",
    "roughness",
    "value_at",
]


def ordered_estimators(names: Iterable[str]) -> tuple[str, ...]:
    """``names`` in display order (each once).

    The paper's estimators come first, in its order, then any other in the given order.
    """
    names = list(dict.fromkeys(names))
    return (
        *(n for n in PAPER_ESTIMATORS if n in names),
        *(n for n in names if n not in PAPER_ESTIMATORS),
    )


def model_estimators(names: Iterable[str]) -> tuple[str, ...]:
    """The model-based estimators (``model_*``) among ``names``, in display order."""
    return tuple(n for n in ordered_estimators(names) if n.startswith("model_"))


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
    # ties (a distance or a step repeated: the detections' and the CSV's rounding) share their
    # mean rank, as Spearman's coefficient defines it
    rho = float(spearmanr(d_step, step).statistic) if len(step) > 2 else float("nan")
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
