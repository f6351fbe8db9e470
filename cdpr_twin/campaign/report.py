"""A campaign's report, computed from its table: distributions, per-axis effects, attributions.

``report.md`` and figures beside ``results.parquet``:

- the headline metric's distribution over the runs (``cp1.t_m``, the platform's true error at
  the first checkpoint — p1 in the open-loop runs — when the runs have checkpoints, else
  ``final_t_m``, the error vs the controller's goal): quantiles and a histogram;
- per grid axis (a varied key with few values, not a seed: a seed names a draw): the
  metric's median and spread per value, and a box plot;
- the estimators, per block: each one's median RMS deviation from ground truth over the runs,
  and in how many runs it deviates least of all (translation, rotation, both) — which
  estimator wins over many robots or noise draws, not over one;
- when the robot varies (``truth.seed``): which calibration error drives the error at the
  checkpoint. Each run's deviations are drawn again from its scenario's truth spec (the draw is
  deterministic), the 3-D error vector is regressed on all of them (least squares), and each
  group's share of the error's variance is ``var(X_g·β_g) / var(y)``, with the fit's R².
"""

from __future__ import annotations

import itertools
import json
import math
import re
from pathlib import Path

import numpy as np

from cdpr_twin.campaign.spec import Campaign
from cdpr_twin.campaign.table import load_table
from cdpr_twin.files.transaction import save_figure, write_atomic

GROUPS = (
    "exit points",
    "anchor points",
    "E·S",
    "sheave radii",
    "camera mount",
    "tag placement",
    "drum radii",
    "homing offset",
)


def _metric(columns: dict) -> tuple[str, str]:
    if "cp1.t_m" in columns and np.isfinite(columns["cp1.t_m"]).any():
        return "cp1.t_m", "true error at the first checkpoint (p1) [mm]"
    return "final_t_m", "final error vs the goal [mm]"


def _quantiles(x: np.ndarray) -> str:
    x = x[np.isfinite(x)]
    if not x.size:
        return "no finite value"
    q = np.percentile(x, [5, 50, 95])
    return (
        f"median {q[1]:.2f}, 5–95 % {q[0]:.2f}–{q[2]:.2f}, max {x.max():.2f} "
        f"(mean {x.mean():.2f}, n = {x.size})"
    )


def deviation_matrix(tasks: dict, rows: list[dict]) -> np.ndarray:
    """Each run's drawn errors, one row per run: (n, 9m + 18).

    Columns: exit points (3m), anchor points (3m), E·S scale − 1 (m), sheave radii (m), camera
    mount (6), tag placement (6), as :class:`~cdpr_twin.robot.deviations.TruthDeviations` holds
    them; the drums' relative radius errors (m), drawn as the twin draws them (the robot's
    winch generator, :func:`cdpr_twin.sim.winch.draw_drum_radii`); the run's homing offset
    (position [m], rotation [deg]: 6), as its ``summary.json`` gives it.
    """
    from cdpr_twin.robot.realism import robot_rng
    from cdpr_twin.scenario.loading import scenario_from_data

    out = []
    for row in rows:
        task = tasks[row["run_id"]]
        scenario = scenario_from_data(task.data, task.source)
        spec = scenario.truth
        summary = json.loads(row["summary"])
        m = len(summary["final_tensions_n"])
        d = spec.draw(m)
        sigma = scenario.realism.winch.drum_radius_error_std
        drums = robot_rng(spec.seed, "winch").normal(0.0, sigma, m)
        homing = summary.get("homing_offset") or {}
        out.append(
            np.concatenate(
                [
                    d.exit_offsets.ravel(),
                    d.anchor_offsets.ravel(),
                    d.es_scale - 1.0,
                    d.pulley_radius_offsets,
                    d.camera_offset,
                    d.tag_offset,
                    drums,
                    homing.get("position_m", np.zeros(3)),
                    homing.get("rotation_deg", np.zeros(3)),
                ]
            )
        )
    return np.array(out)


def group_columns(m: int) -> dict[str, slice]:
    """Each deviation group's columns of :func:`deviation_matrix` (m cables), in its order."""
    sizes = (3 * m, 3 * m, m, m, 6, 6, m, 6)
    ends = np.cumsum(sizes)
    return {g: slice(int(e - n), int(e)) for g, n, e in zip(GROUPS, sizes, ends, strict=True)}


def attribution(X: np.ndarray, Y: np.ndarray, m: int) -> tuple[dict[str, float], float]:
    """Variance shares of each deviation group in a linear fit of ``Y`` (n, 3) on ``X``.

    Returns:
        ``({group: share}, R²)``; shares of the total variance of ``Y`` (summed over axes).
    """
    Xc, Yc = X - X.mean(axis=0), Y - Y.mean(axis=0)
    beta, *_ = np.linalg.lstsq(Xc, Yc, rcond=None)
    total = float(np.sum(Yc.var(axis=0)))
    shares = {}
    for name, cols in group_columns(m).items():
        part = Xc[:, cols] @ beta[cols]
        varied = np.any(np.ptp(X[:, cols], axis=0) > 0.0)
        # a group the runs share (e.g. one homing offset for all) has no share: NaN
        shares[name] = float(np.sum(part.var(axis=0)) / total) if total > 0 and varied else math.nan
    residual = Yc - Xc @ beta
    return shares, 1.0 - float(np.sum(residual.var(axis=0)) / total) if total > 0 else math.nan


ATTRIBUTION_RESAMPLES = 400
"""Bootstrap resamples of the robots behind each variance share's interval."""
NULL_SHUFFLES = 100
"""Shuffles of a group's draws behind its share's no-effect quantile."""


def attribution_intervals(
    X: np.ndarray, Y: np.ndarray, m: int, confidence: float = 0.95, seed: int = 0
) -> dict[str, tuple[float, float]]:
    """Each group's share of :func:`attribution` with its percentile bootstrap interval.

    The robots (rows) are resampled with replacement and the fit redone on each resample; the
    generator is seeded, so the same table gives the same intervals.

    Args:
        X: (n, 9m + 18) the drawn deviations (:func:`deviation_matrix`).
        Y: (n, 3) the error at p1 [m].
        m: cables.
        confidence: the intervals' level.
        seed: the resampling generator's seed.

    Returns:
        ``{group: (low, high)}`` (NaN for a group the runs share).
    """
    rng = np.random.default_rng(seed)
    n = len(X)
    draws = [attribution(X[i], Y[i], m)[0] for i in rng.integers(0, n, (ATTRIBUTION_RESAMPLES, n))]
    q = ((1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0)
    out: dict[str, tuple[float, float]] = {}
    for g in GROUPS:
        v = np.array([d[g] for d in draws])
        if np.isnan(v).all():
            out[g] = (math.nan, math.nan)
        else:
            low, high = np.quantile(v, q)
            out[g] = (float(low), float(high))
    return out


def _miss_vectors(rows: list[dict]) -> np.ndarray:
    out = []
    for row in rows:
        cp = json.loads(row["summary"])["segment_ends"][0]
        out.append(np.subtract(cp["true_pose"][:3], cp["waypoint"][:3]))
    return np.array(out)


NO_FIGURE = "(figure not drawn: matplotlib is not installed; pip install 'cdpr-twin[plots]')"
"""What the report says where a figure would be, without the ``plots`` extra."""


def _figure(path: Path, draw, alt: str) -> str:
    """Draw a figure into ``path``; its Markdown line (a note when matplotlib is absent)."""
    try:
        import matplotlib
    except ModuleNotFoundError:
        return NO_FIGURE
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=110)
    draw(ax)
    fig.tight_layout()
    try:
        save_figure(fig, path, format="png")
    finally:
        plt.close(fig)
    return f"![{alt}]({path.name})"


def _axis_section(columns: dict, key: str, metric: str, label: str, out: Path) -> list[str]:
    values = columns[f"param.{key}"]
    levels = _levels(values)
    y = columns[metric] * 1e3
    lines = [f"### Effect of `{key}`", "", f"| {key} | runs | {label} |", "|---|---|---|"]
    groups = []
    for v in levels:
        sel = values == v
        groups.append(y[sel & np.isfinite(y)])
        lines.append(f"| {v} | {int(sel.sum())} | {_quantiles(y[sel])} |")
    name = f"effect_{key.replace('.', '_')}.png"

    def draw(ax):
        ax.boxplot(groups, tick_labels=[str(v) for v in levels])
        ax.set_xlabel(key)
        ax.set_ylabel(label)

    return [*lines, "", _figure(out / name, draw, key), ""]


def _levels(values: np.ndarray) -> list:
    """A column's distinct values, numbers in numeric order (missing values left out).

    A run without the key (another block's) has ``None`` or NaN there.
    """
    present = {v for v in values.tolist() if v is not None and v == v}
    if all(isinstance(v, int | float) for v in present):
        return sorted(present)
    return sorted(present, key=str)


def axis_cells(columns: dict, ok: np.ndarray, key: str, factors: list[str], metric: str) -> dict:
    """An axis's effect within each combination of the other factors (interactions shown).

    Args:
        columns: the table's columns (``param.<key>``, the factors', ``metric`` and its rotation
            twin ``…r_deg`` beside ``…t_m``).
        ok: (n,) the runs that ran.
        key: the axis (dotted scenario key).
        factors: the other columns that split the runs (``block``, ``param.<other axis>``).
        metric: the translation column (``cp1.t_m`` or ``final_t_m``).

    Returns:
        ``{cell: {level: (median translation [mm], median rotation [deg], runs)}}``, a cell
        being the factors' values (a tuple, in ``factors`` order; ``None`` where the runs do
        not have the factor: a block that does not vary that axis); medians over the runs
        that ran with a finite metric.
    """
    values, t = columns[f"param.{key}"], columns[metric].astype(float)
    r = columns[metric[: -len("t_m")] + "r_deg"].astype(float)
    keep = ok & np.isfinite(t)
    missing = {f: np.array([v is None or v != v for v in columns[f].tolist()]) for f in factors}
    cells: dict = {}
    levels = [_levels(columns[f][keep]) + [None][: int(missing[f][keep].any())] for f in factors]
    for cell in itertools.product(*levels):
        in_cell = keep.copy()
        for f, v in zip(factors, cell, strict=True):
            in_cell &= missing[f] if v is None else columns[f] == v
        row = {
            level: (float(np.median(t[sel]) * 1e3), float(np.median(r[sel])), int(sel.sum()))
            for level in _levels(values[in_cell])
            if (sel := in_cell & (values == level)).any()
        }
        if row:
            cells[cell] = row
    return cells


def _interaction_section(
    columns: dict, ok: np.ndarray, key: str, others: list[str], metric: str
) -> list[str]:
    factors = (["block"] if len(_levels(columns["block"][ok])) > 1 else []) + others
    if not factors:
        return []
    cells = axis_cells(columns, ok, key, factors, metric)
    levels = _levels(columns[f"param.{key}"][ok])
    heads = [f.removeprefix("param.") for f in factors]
    lines = [
        f"By {', '.join(f'`{h}`' for h in heads)}: median translation / rotation "
        f"({'at p1' if metric.startswith('cp1') else 'final, vs the goal'}) and runs, per "
        f"value of `{key}`:",
        "",
        "| " + " | ".join([*heads, *(str(v) for v in levels)]) + " |",
        "|" + "---|" * (len(heads) + len(levels)),
    ]
    for cell, row in cells.items():
        entries = [
            f"{row[v][0]:.2f} mm / {row[v][1]:.3f}° ({row[v][2]})" if v in row else "–"
            for v in levels
        ]
        names = ["–" if c is None else str(c) for c in cell]
        lines.append("| " + " | ".join([*names, *entries]) + " |")
    return [*lines, ""]


ATTRIBUTION_MIN_ROBOTS = 100
"""Runs a block needs for its attribution: 90 regressors (eight cables) want ten times as many."""


def _attribution_section(campaign: Campaign, rows: list[dict]) -> list[str]:
    """The variance attribution of the error at p1, block by block.

    A block is one population, drawn to one set of tolerances: runs of several blocks (other
    tolerances, repetitions of a few robots) do not make one sample of deviations, and a
    regression over them fits their mixture, not a population (shares well above 100 %).
    """
    tasks = {t.run_id: t for t in campaign.tasks}
    rows = [r for r in rows if r["ok"] and r["run_id"] in tasks and r.get("cp1.t_m") is not None]
    blocks: dict[str, list[dict]] = {}
    for r in rows:
        blocks.setdefault(str(r.get("block")), []).append(r)
    lines: list[str] = []
    for block, block_rows in blocks.items():
        if len(block_rows) >= ATTRIBUTION_MIN_ROBOTS:
            title = "" if len(blocks) == 1 else f" (block `{block}`)"
            lines += _attribution(tasks, block_rows, title)
    return lines


def attribution_nulls(
    X: np.ndarray, Y: np.ndarray, m: int, confidence: float = 0.95, seed: int = 0
) -> dict[str, float]:
    """Each group's share when it cannot matter: the ``confidence`` quantile under permutation.

    A share is a variance, never below 0, and a fit lends every group some of the noise (about
    its columns / n of the unexplained variance): a small share is told apart from no effect
    only above what the same group gets with its rows shuffled across the robots (its draws
    kept, their link to the error broken), refitted ``NULL_SHUFFLES`` times.

    Returns:
        ``{group: share quantile}`` (NaN for a group the runs share).
    """
    rng = np.random.default_rng(seed)
    out = {}
    for g, cols in group_columns(m).items():
        if not np.any(np.ptp(X[:, cols], axis=0) > 0.0):
            out[g] = math.nan
            continue
        draws = []
        for _ in range(NULL_SHUFFLES):
            Xp = X.copy()
            Xp[:, cols] = X[rng.permutation(len(X)), cols]
            draws.append(attribution(Xp, Y, m)[0][g])
        out[g] = float(np.quantile(draws, confidence))
    return out


def _attribution(tasks: dict, rows: list[dict], title: str) -> list[str]:
    X, Y = deviation_matrix(tasks, rows), _miss_vectors(rows)
    m = len(json.loads(rows[0]["summary"])["final_tensions_n"])
    shares, r2 = attribution(X, Y, m)
    ci = attribution_intervals(X, Y, m)
    null = attribution_nulls(X, Y, m)
    lines = [
        f"## Which calibration error drives the error at p1{title}",
        "",
        f"Linear least squares of the 3-D error at the first checkpoint on the {X.shape[1]} "
        f"drawn deviations of each of the {len(rows)} robots (R² = {r2:.3f}); each group's "
        "share of the error's variance, with its 95 % bootstrap interval (the robots resampled "
        f"{ATTRIBUTION_RESAMPLES} times). A share is never below 0 and the fit lends every "
        "group some noise: a share at or below what the group gets with its draws shuffled "
        f"across the robots (the 95 % quantile of {NULL_SHUFFLES} shuffles) is *not told "
        "apart from 0*.",
        "",
        "| deviation group | share of variance | 95 % interval | shuffled, 95 % |",
        "|---|---|---|---|",
    ]
    varied = {g: s for g, s in shares.items() if not math.isnan(s)}
    for g, share in sorted(varied.items(), key=lambda kv: -kv[1]):
        mark = " *not told apart from 0*" if share <= null[g] else ""
        lines.append(
            f"| {g} | {100 * share:.1f} %{mark} | [{100 * ci[g][0]:.1f}, {100 * ci[g][1]:.1f}] % "
            f"| {100 * null[g]:.2f} % |"
        )
    if same := [g for g in shares if g not in varied]:
        lines += ["", f"The same in every run (no share): {', '.join(same)}."]
    return [*lines, ""]


def _failure_section(columns: dict, ok: np.ndarray) -> list[str]:
    """Why runs failed: each distinct error, its run count and the first runs' names."""
    errors: dict[str, list[str]] = {}
    for name, error in zip(columns["name"][~ok], columns["error"][~ok], strict=True):
        errors.setdefault(str(error), []).append(str(name))
    if not errors:
        return []
    lines = ["## Failed runs", "", "| runs | error | e.g. |", "|---|---|---|"]
    for error, names in sorted(errors.items(), key=lambda kv: -len(kv[1])):
        shown = ", ".join(f"`{n}`" for n in names[:3]) + (", …" if len(names) > 3 else "")
        lines.append(f"| {len(names)} | {error.replace('|', '/')} | {shown} |")
    return [*lines, ""]


def cpu_time(seconds: float) -> str:
    """The runs' summed time, in the unit that shows it: CPU-s below a minute, else CPU-min.

    A campaign of short runs took seconds: in minutes to one decimal it read "0.0 CPU-min".
    """
    if seconds < 60:
        return f"{seconds:.1f} CPU-s"
    return f"{seconds / 60:.1f} CPU-min"


def report_files(out: Path) -> list[Path]:
    """What :func:`write_report` writes into ``out``: ``report.md`` and its figures."""
    return [out / "report.md", out / "distribution.png", *sorted(out.glob("effect_*.png"))]


def write_report(out: str | Path, campaign: Campaign) -> Path:
    """Compute ``report.md`` and its figures from the campaign's table; returns its path."""
    out = Path(out)
    table = load_table(out)
    rows = table.to_pylist()
    columns = {
        c: np.array(table.column(c).to_pylist(), dtype=float if _numeric(table, c) else object)
        for c in table.column_names
    }
    metric, label = _metric(columns)
    y = columns[metric] * 1e3
    ok = columns["ok"].astype(bool)
    faults = [f for f in columns["fault"].tolist() if f]

    def hist(ax):
        ax.hist(y[np.isfinite(y)], bins=min(50, max(5, int(np.sqrt(ok.sum())))))
        ax.set_xlabel(label)
        ax.set_ylabel("runs")

    lines = [
        f"# Campaign `{campaign.name}`",
        "",
        campaign.description,
        "",
        f"{len(rows)} runs: {int(ok.sum())} ran, {int((~ok).sum())} failed, "
        f"{len(faults)} stopped by a fault of the robot"
        + (f" ({', '.join(sorted(set(faults)))})" if faults else "")
        + f". Total run time {cpu_time(np.nansum(columns['wall_time_s']))}.",
        "",
        f"## {label[0].upper()}{label[1:]}",
        "",
        _quantiles(y),
        "",
        _figure(out / "distribution.png", hist, "distribution"),
        "",
    ]
    grid = [  # grid axes: few values, each repeated; a seed names a draw (its spread: above)
        c
        for c in table.column_names
        if c.startswith("param.")
        and not c.endswith("seed")
        and c != "param.sample"
        and 1 < len(_levels(columns[c])) <= min(20, len(rows) - 1)
    ]
    for c in grid:
        lines += _axis_section(columns, c[len("param.") :], metric, label, out)
        others = [o for o in grid if o != c]
        lines += _interaction_section(columns, ok, c[len("param.") :], others, metric)
    lines += _estimator_section(columns, ok)
    lines += _attribution_section(campaign, rows)
    lines += _failure_section(columns, ok)
    return write_atomic(out / "report.md", "\n".join(lines) + "\n")


def estimator_wins(columns: dict, ok: np.ndarray, block: str | None = None) -> dict:
    """Per estimator: median RMS deviations and the runs in which it deviates least.

    The estimators compared are those every run that ran (in the block) reports: a block with
    the camera off has no ``image``, and a block varying the camera compares the others.

    Args:
        columns: the table's columns (``est.<name>.rms_t_m`` / ``rms_r_deg`` per estimator).
        ok: (n,) the runs that ran.
        block: only this block's runs (``None``: all).

    Returns:
        ``{"runs": n, "estimators": {name: {"rms_t_mm", "rms_r_deg" (medians), "best_t",
        "best_r", "best_both" (run counts)}}}`` (a strict minimum: a tie is nobody's win).
    """
    keep = ok.copy()
    if block is not None:
        keep &= columns["block"] == block

    def reported(name: str) -> bool:  # by every run kept
        t, r = columns[f"est.{name}.rms_t_m"][keep], columns[f"est.{name}.rms_r_deg"][keep]
        return bool(np.isfinite(t.astype(float)).all() and np.isfinite(r.astype(float)).all())

    column = re.compile(r"est\.(.+)\.rms_t_m")
    candidates = [m.group(1) for c in sorted(columns) if (m := column.fullmatch(c))]
    names = [n for n in candidates if reported(n)] if keep.any() else []
    if not names:
        return {"runs": 0, "estimators": {}}
    T = np.column_stack([columns[f"est.{n}.rms_t_m"][keep] for n in names]).astype(float)
    R = np.column_stack([columns[f"est.{n}.rms_r_deg"][keep] for n in names]).astype(float)

    def strict_best(X: np.ndarray) -> np.ndarray:  # (runs, names): strictly below every other
        return X < np.where(np.eye(len(names), dtype=bool)[None], np.inf, X[:, None, :]).min(2)

    bt, br = strict_best(T), strict_best(R)
    table = {
        n: {
            "rms_t_mm": float(np.median(T[:, i]) * 1e3),
            "rms_r_deg": float(np.median(R[:, i])),
            "best_t": int(bt[:, i].sum()),
            "best_r": int(br[:, i].sum()),
            "best_both": int((bt[:, i] & br[:, i]).sum()),
        }
        for i, n in enumerate(names)
    }
    return {"runs": int(keep.sum()), "estimators": table}


def _estimator_section(columns: dict, ok: np.ndarray) -> list[str]:
    """Which estimator deviates least, run by run, in each block."""
    lines: list[str] = []
    for block in sorted(set(columns["block"].tolist())):
        wins = estimator_wins(columns, ok, block)
        if len(wins["estimators"]) < 2 or not wins["runs"]:
            continue
        lines += [
            f"## Estimators ({block}): which deviates least from ground truth",
            "",
            f"Over its {wins['runs']} runs that ran: each estimator's median RMS deviation over "
            "its run, and the runs in which it deviates less than every other estimator (by any "
            "margin: model variants can differ by a thousandth of a degree).",
            "",
            "| estimator | median RMS translation | median RMS rotation | least in translation "
            "| least in rotation | least in both |",
            "|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {n} | {e['rms_t_mm']:.2f} mm | {e['rms_r_deg']:.3f}° | {e['best_t']} | "
            f"{e['best_r']} | {e['best_both']} |"
            for n, e in wins["estimators"].items()
        ]
        lines.append("")
    return lines


def _numeric(table, column: str) -> bool:
    import pyarrow as pa

    t = table.schema.field(column).type
    return pa.types.is_floating(t) or pa.types.is_integer(t)
