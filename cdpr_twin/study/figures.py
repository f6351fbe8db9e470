"""The paper's figures from run outputs (matplotlib, no display needed).

Each function takes loaded results and a path, writes a PNG of ``FIGSIZE`` × ``DPI`` pixels and
returns the path: Fig. 5a/5b (open loop), Fig. 7a/7b (PBVS), Fig. 8 (accuracy at p1).

Figures are :class:`matplotlib.figure.Figure` objects saved directly: no pyplot, no backend
chosen at import, no global state, so importing this module changes nothing for the caller.
Estimators the paper does not have get colours from :data:`EXTRA_COLORS`, their name as label.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cdpr_twin.files.transaction import save_figure
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run.metrics import sample_std
from cdpr_twin.study.results import ordered_estimators

FIGSIZE = (12.0, 6.0)
"""Figure size [in]."""
DPI = 100
"""Resolution: figures are 1200 × 600 px."""
COLORS = {
    "true": "#1f3fbf",
    "plan": "#17becf",
    "control": "#2ca02c",
    "image": "#e377c2",
    "model_simple": "#ff7f0e",
    "model_elastic": "#d62728",
    "model_pulley": "#9467bd",
    "model_elastic_pulley": "#8c564b",
}
LABELS = {
    "true": "measured (ground truth)",
    "plan": "planned",
    "control": "Est. 1 control",
    "image": "Est. 2 image",
    "model_simple": "Est. 3 simple",
    "model_elastic": "Est. 4 elastic",
    "model_pulley": "Est. 5 pulley",
    "model_elastic_pulley": "Est. 6 elastic+pulley",
}
EXTRA_COLORS = ("#bcbd22", "#7f7f7f", "#1f77b4", "#393b79", "#637939", "#843c39", "#7b4173")
"""Colours of other estimators, in order of first use (none is one of :data:`COLORS`)."""


class _Palette:
    """Colour by name: :data:`COLORS`, else the next of :data:`EXTRA_COLORS` (cycled)."""

    def __init__(self) -> None:
        self._extra: dict[str, str] = {}

    def __call__(self, key: str) -> str:
        if key in COLORS:
            return COLORS[key]
        if key not in self._extra:
            self._extra[key] = EXTRA_COLORS[len(self._extra) % len(EXTRA_COLORS)]
        return self._extra[key]


def _key(label: str) -> str:
    """The estimator (or ``true``/``plan``) a curve label is about: ``"image in loop"`` → image."""
    return label.split(" ")[0]


def _save(fig: Figure, path: Path) -> Path:
    """Save whole: into ``<path>.partial`` (format from ``path``'s suffix), then renamed.

    Raises:
        cdpr_twin.files.transaction.OutputError: the write failed (disk full); ``path`` is not
            touched.
    """
    return save_figure(fig, Path(path), dpi=DPI, format=Path(path).suffix.lstrip(".") or "png")


def trajectories_3d(curves: dict[str, np.ndarray], title: str, path: Path) -> Path:
    """3D platform trajectories (Fig. 5a / 7a).

    Args:
        curves: label → (n, 3) positions [m] (NaN rows are skipped).
        title: figure title.
        path: output PNG.
    """
    fig = Figure(figsize=FIGSIZE)
    ax = fig.add_subplot(projection="3d")
    color = _Palette()
    for label, p in curves.items():
        ok = np.all(np.isfinite(p), axis=1)
        key = _key(label)
        ax.plot(
            *(p[ok] * 100).T,
            label=LABELS.get(label, label),
            color=color(key),
            lw=2.0 if key == "true" else 1.2,
        )
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    ax.set_zlabel("z [cm]")
    ax.view_init(elev=22, azim=-58)
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8, bbox_to_anchor=(0.0, 1.0))
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.02, top=0.94)
    return _save(fig, path)


def deviations(
    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    title: str,
    path: Path,
    marks: tuple[float, ...] = (),
) -> Path:
    """Translational and rotational deviation from ground truth over time (Fig. 5b / 7b).

    Args:
        series: label → (t [s], translation [m], rotation [rad]).
        title: figure title.
        path: output PNG.
        marks: times to mark with dotted vertical lines (segment ends).
    """
    fig = Figure(figsize=FIGSIZE)
    a, b = fig.subplots(2, 1, sharex=True)
    color = _Palette()
    for label, (t, dt, dr) in series.items():
        c = color(_key(label))
        a.plot(t, dt * 1e3, label=LABELS.get(label, label), color=c, lw=1)
        b.plot(t, np.degrees(dr), color=c, lw=1)
    for ax in (a, b):
        for m in marks:
            ax.axvline(m, color="k", ls=":", lw=1)
        ax.grid(alpha=0.3)
    a.set_ylabel("translation [mm]")
    b.set_ylabel("rotation [deg]")
    b.set_xlabel("time [s]")
    a.set_title(title)
    a.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    return _save(fig, path)


def accuracy_bars(groups: dict[str, dict[str, list[float]]], path: Path) -> Path:
    """Final accuracy at p1: mean and spread over repetitions (Fig. 8).

    Args:
        groups: each column's label → {"translation_m": [...], "rotation_deg": [...]}.
        path: output PNG.
    """
    fig = Figure(figsize=FIGSIZE)
    a, b = fig.subplots(1, 2)
    labels = list(groups)
    x = np.arange(len(labels))
    for ax, key, scale, unit in (
        (a, "translation_m", 1e3, "translation error [mm]"),
        (b, "rotation_deg", 1.0, "rotation error [deg]"),
    ):
        means = [np.mean(groups[k][key]) * scale if groups[k][key] else np.nan for k in labels]
        stds = [sample_std(groups[k][key]) * scale for k in labels]
        colors = ["#7f7f7f" if k.startswith("open") else "#1f77b4" for k in labels]
        ax.bar(x, means, yerr=stds, capsize=4, color=colors)
        for xi, k in zip(x, labels, strict=True):
            ax.plot([xi] * len(groups[k][key]), np.array(groups[k][key]) * scale, "k.", ms=4)
        ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(unit)
        ax.grid(axis="y", alpha=0.3)
    a.set_title("MP pose accuracy at p1 (mean ± std, dots: runs)")
    fig.tight_layout()
    return _save(fig, path)


def open_loop_figures(ts: Timeseries, out: Path, marks: tuple[float, ...] = ()) -> list[Path]:
    """Fig. 5a and 5b of one open-loop run (``marks``: segment ends [s], dotted in Fig. 5b)."""
    names = ordered_estimators(ts.estimator_names)
    curves = {"true": ts.poses("true")[:, :3, 3], "plan": ts.poses("plan")[:, :3, 3]}
    curves.update({n: ts.poses(n)[:, :3, 3] for n in names})
    series = {n: (ts.t, *ts.deviation(n)) for n in names}
    return [
        trajectories_3d(curves, "Open loop: MP trajectories (Fig. 5a)", out / "fig5a.png"),
        deviations(
            series, "Open loop: estimate − C-Track truth (Fig. 5b)", out / "fig5b.png", marks
        ),
    ]


def pbvs_figures(runs: dict[str, Timeseries], out: Path) -> list[Path]:
    """Fig. 7a and 7b: one PBVS run per in-loop estimator (``runs``: in-loop name → run)."""
    curves = {f"{n} in loop": ts.poses("true")[:, :3, 3] for n, ts in runs.items()}
    series = {f"{n} in loop": (ts.t, *ts.deviation(n)) for n, ts in runs.items()}
    return [
        trajectories_3d(
            curves,
            "PBVS: measured MP trajectories, each estimator in the loop (Fig. 7a)",
            out / "fig7a.png",
        ),
        deviations(series, "PBVS: in-loop estimate − truth (Fig. 7b)", out / "fig7b.png"),
    ]
