"""The paper's findings over populations of robots: per-run metrics, shares, intervals.

The population is a campaign (``campaigns/paper_population.toml``) run by the campaign engine
(local processes, or Ray), resumed: runs already in its directory are kept, so the study's
report is recomputed without rerunning them. Each run's metrics (:func:`open_loop_metrics`,
:func:`pbvs_metrics`) come from its ``summary.json`` and, where the camera or a whole-run
quantity is needed, its ``timeseries.csv``. The criteria file (:mod:`.criteria`) says which
metric of which block each finding is judged on; :func:`population_report` applies it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cdpr_twin.estimators import PAPER_ESTIMATORS
from cdpr_twin.resources import campaigns_dir
from cdpr_twin.study.criteria import Rule, judge, load_criteria

POPULATION_CAMPAIGN = campaigns_dir() / "paper_population.toml"
"""The population's campaign file (shipped with the package, as every campaign)."""
ILLUSTRATION_ROBOT = 19
"""The truth seed of the study's single robot (its figures): chosen for its ≈ 1 cm miss."""
BOOTSTRAP_RESAMPLES = 2000
"""Resamples of every bootstrap interval (SciPy's BCa)."""
BOOTSTRAP_SEED = 2021
"""The bootstrap's seed: the same runs give the same intervals."""


def _load(run_dir: Path):
    from cdpr_twin.recording.timeseries import Timeseries

    return Timeseries.load(run_dir / "timeseries.csv")


def vector_roughness(ts, name: str) -> float:
    """RMS over ticks of ‖Δ(p̂ − p)‖, the change of the translational deviation *vector* [m]."""
    dev = ts.poses(name)[:, :3, 3] - ts.poses("true")[:, :3, 3]
    step = np.linalg.norm(np.diff(dev, axis=0), axis=1)
    step = step[np.isfinite(step)]
    return float(np.sqrt(np.mean(step**2))) if len(step) else math.nan


def image_distance_ratios(ts) -> tuple[float, float]:
    """The image estimate far from the tag against near it: (noise ratio, error ratio).

    Ticks are split by the detected camera–tag distance ‖ᶜt_o‖ into thirds; noise is the vector
    roughness (:func:`vector_roughness`) within a third, error the RMS translational deviation.
    Returns the farthest third's over the nearest third's (NaN without detections).
    """
    dist = np.sqrt(sum(ts.columns[f"tag_{k}"] ** 2 for k in "xyz"))
    dev = ts.poses("image")[:, :3, 3] - ts.poses("true")[:, :3, 3]
    step = np.linalg.norm(np.diff(dev, axis=0), axis=1)
    err = np.linalg.norm(dev, axis=1)
    ok = np.isfinite(dist[1:]) & np.isfinite(step)
    d, s, e = dist[1:][ok], step[ok], err[1:][ok]
    if len(d) < 3:
        return math.nan, math.nan
    order = np.argsort(d)
    third = len(order) // 3
    near, far = order[:third], order[-third:]
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    return rms(s[far]) / rms(s[near]), rms(e[far]) / rms(e[near])


def nees(ts, name: str = "fused") -> tuple[np.ndarray, np.ndarray]:
    """Each tick's NEES ε = δᵀ P⁻¹ δ (δ = log(T̂⁻¹ T), F_p) and each axis's δ_i² / P_ii.

    Returns:
        ``(ε (K,), normalised squared errors (K, 6))``; ticks without a covariance are left out.
    """
    from cdpr_twin.math.se3 import inverse, se3_log

    T_hat, T = ts.poses(name), ts.poses("true")
    P = ts.covariance(name)
    ok = np.all(np.isfinite(T_hat), axis=(1, 2)) & np.all(np.isfinite(P), axis=(1, 2))
    delta = np.array([se3_log(inverse(a) @ b) for a, b in zip(T_hat[ok], T[ok], strict=True)])
    eps = np.einsum("ki,kij,kj->k", delta, np.linalg.inv(P[ok]), delta)
    return eps, delta**2 / np.einsum("kii->ki", P[ok])


def nees_bounds(confidence: float, dof: int = 6, runs: int = 1) -> tuple[float, float]:
    """The two-sided χ² interval of an average NEES over ``runs`` runs of a ``dof`` error."""
    from scipy.stats import chi2

    tail = 0.5 * (1.0 - confidence)
    return chi2.ppf(tail, dof * runs) / runs, chi2.ppf(1.0 - tail, dof * runs) / runs


def _image_over_others(rough: dict[str, float]) -> float:
    """The image estimate's roughness over the largest of the others'."""
    return rough["image"] / max(v for n, v in rough.items() if n != "image")


def _paper(names, *drop: str) -> list[str]:
    return [n for n in names if n in PAPER_ESTIMATORS and n not in drop]


def _gains(est: dict, name: str = "fused") -> dict[str, float]:
    """Best other estimator's RMS deviation over ``name``'s (translation, rotation)."""
    if name not in est or len(est) < 2:
        return {}
    out = {}
    for key, q in (("rms_translation_m", "t"), ("rms_rotation_deg", "r")):
        others = [v[key] for n, v in est.items() if n != name and key in v]
        out[f"fused_gain_{q}"] = min(others) / est[name][key] if others else math.nan
    return out


def open_loop_metrics(run_dir: Path, confidence: float, whole_run: bool = True) -> dict:
    """The open-loop metrics of one run (p0 → p1): see ``criteria.toml``'s list.

    Args:
        run_dir: the run's directory (``summary.json``; ``timeseries.csv`` for whole-run ones).
        confidence: the NEES interval's level.
        whole_run: also the metrics that need the time series.
    """
    s = json.loads((run_dir / "summary.json").read_text("utf-8"))
    est = s["estimators"]
    ends = s.get("segment_ends") or []
    if not ends:
        return {}
    end = ends[0]
    miss = end["truth_vs_waypoint"]["translation_m"]
    m: dict = {
        "open_loop_miss_m": miss,
        "open_loop_miss_deg": end["truth_vs_waypoint"]["rotation_deg"],
    }
    followers = _paper(end["estimates_vs_plan"], "image")
    if followers:
        worst = max(end["estimates_vs_plan"][n]["translation_m"] for n in followers)
        m["follow_plan_ratio"] = worst / miss
    models = [n for n in _paper(est) if n.startswith("model_")]
    if models and "control" in est:
        best = min(est[n]["rms_translation_m"] for n in models)
        m["model_over_control_rms"] = best / est["control"]["rms_translation_m"]
    m |= _gains(est)
    if not whole_run:
        return m
    ts = _load(run_dir)
    if len(models) > 1:
        P = np.array([ts.poses(n)[:, :3, 3] for n in models])
        pairwise = max(
            float(np.nanmax(np.linalg.norm(P[i] - P[j], axis=1)))
            for i in range(len(models))
            for j in range(i + 1, len(models))
        )
        m["model_spread_ratio"] = pairwise / max(est[n]["max_translation_m"] for n in models)
    if "image" in est and s.get("camera"):
        rough = {n: vector_roughness(ts, n) for n in _paper(est)}
        m["image_roughness_ratio"] = _image_over_others(rough)
        m["image_noise_far_near"], m["image_error_far_near"] = image_distance_ratios(ts)
    if "fused" in est and "fused_cov_x_x" in ts.columns:
        eps, axes = nees(ts)
        low, high = nees_bounds(confidence)
        m["nees_in_bounds"] = float(np.mean((eps >= low) & (eps <= high)))
        m["nees_mean"] = float(np.mean(eps))
        m["nees_axes"] = np.mean(axes, axis=0).tolist()
        m["nees"] = eps.tolist()
    return m


def pbvs_metrics(run_dir: Path, whole_run: bool = True) -> dict:
    """The PBVS metrics of one run (control in the loop, the others passive)."""
    s = json.loads((run_dir / "summary.json").read_text("utf-8"))
    est, in_loop = s["estimators"], s["in_loop"]
    err = s["final_error_vs_goal"]
    m: dict = {
        "converged": s["status"] == "converged",
        "pbvs_error_m": err["translation_m"],
        "pbvs_error_deg": err["rotation_deg"],
    }
    others = _paper(est, in_loop)
    if in_loop == "control" and others:
        m["control_over_best_max"] = est["control"]["max_translation_m"] / min(
            est[n]["max_translation_m"] for n in others
        )
    m |= _gains(est)
    if whole_run and "image" in est:
        ts = _load(run_dir)
        rough = {n: vector_roughness(ts, n) for n in _paper(est)}
        m["image_roughness_ratio"] = _image_over_others(rough)
    return m


def collect(out: Path, confidence: float) -> dict[str, list[dict]]:
    """Every run's metrics by block: ``{block: [{"truth_seed", "seed", "ok", …metrics}]}``.

    Blocks whose name starts with ``robots_`` get the whole-run metrics (time series); the
    repetition blocks those of ``summary.json``; the sensitivity blocks (``tolerances_*``,
    ``profile_*``) those too and the model variants' spread.
    """
    from cdpr_twin.campaign import load_table

    rows = load_table(out).to_pylist()
    blocks: dict[str, list[dict]] = {}
    for row in rows:
        run = {
            "truth_seed": int(row["param.truth.seed"]),
            "seed": int(row["param.seed"]),
            "ok": bool(row["ok"]),
            "status": row["status"],
        }
        run_dir = out / "runs" / row["run_id"]
        if run["ok"] and (run_dir / "summary.json").is_file():
            pbvs = row["block"].startswith(("robots_pbvs", "repeat_pbvs"))
            whole = row["block"].startswith("robots_")
            if pbvs:
                run |= pbvs_metrics(run_dir, whole)
            else:
                sensitivity = row["block"].startswith(("tolerances_", "profile_"))
                run |= open_loop_metrics(run_dir, confidence, whole or sensitivity)
        blocks.setdefault(row["block"], []).append(run)
    for runs in blocks.values():
        runs.sort(key=lambda r: (r["truth_seed"], r["seed"]))
    _pair_accuracy(blocks)
    return blocks


def _pair_accuracy(blocks: dict[str, list[dict]]) -> None:
    """Each PBVS robot's open-loop / PBVS error ratios, from its own open-loop run."""
    ol = {r["truth_seed"]: r for r in blocks.get("robots_open_loop", []) if "open_loop_miss_m" in r}
    for r in blocks.get("robots_pbvs", []):
        o = ol.get(r["truth_seed"])
        if o is None or "pbvs_error_m" not in r:
            continue
        r["accuracy_ratio_t"] = o["open_loop_miss_m"] / r["pbvs_error_m"]
        r["accuracy_ratio_r"] = o["open_loop_miss_deg"] / r["pbvs_error_deg"]


def values(runs: list[dict], metric: str) -> np.ndarray:
    """A metric over a block's runs (NaN where a run lacks it)."""
    out = [r.get(metric) for r in runs]
    return np.array([math.nan if v is None else float(v) for v in out])


def bootstrap_interval(samples: tuple, statistic: Callable, confidence: float) -> tuple:
    """SciPy's BCa bootstrap interval of ``statistic(*samples, axis)`` (independent samples)."""
    from scipy.stats import bootstrap

    res = bootstrap(
        samples,
        statistic,
        confidence_level=confidence,
        n_resamples=BOOTSTRAP_RESAMPLES,
        paired=False,
        rng=np.random.default_rng(BOOTSTRAP_SEED),
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def _std(x, axis=-1):
    return np.std(x, ddof=1, axis=axis)


def _share(x_all, x_without, axis=-1):
    return 1.0 - np.var(x_without, ddof=1, axis=axis) / np.var(x_all, ddof=1, axis=axis)


REPETITIONS = {"open loop": "repeat_open_loop", "PBVS control": "repeat_pbvs"}
"""The repetition blocks (30 runs on each of a few robots) by controller."""
ERRORS = {
    "repeat_open_loop": ("open_loop_miss_m", "open_loop_miss_deg"),
    "repeat_pbvs": ("pbvs_error_m", "pbvs_error_deg"),
}


def repeatability(blocks: dict[str, list[dict]], confidence: float) -> list[dict]:
    """Per controller and robot: the final error's spread, and each source's share of it.

    The spread is the sample std with its bootstrap interval; a per-run source's share of the
    variance is 1 − Var without / Var all, with its two-sample bootstrap interval.

    Returns:
        Rows ``{"controller", "truth_seed", "n", "quantity", "std", "std_ci", "shares":
        {source: (share, (low, high), n)}}``.
    """
    rows = []
    for controller, block in REPETITIONS.items():
        runs = [r for r in blocks.get(block, []) if r.get("converged", True)]
        for seed in sorted({r["truth_seed"] for r in runs}):
            for metric in ERRORS[block]:
                x = values([r for r in runs if r["truth_seed"] == seed], metric)
                x = x[np.isfinite(x)]
                if len(x) < 3:
                    continue
                row = {
                    "controller": controller,
                    "truth_seed": seed,
                    "n": len(x),
                    "quantity": metric,
                    "mean": float(np.mean(x)),
                    "std": float(_std(x)),
                    "std_ci": bootstrap_interval((x,), _std, confidence),
                    "shares": {},
                }
                for other, wo_runs in blocks.items():
                    if not other.startswith(block + "_without_"):
                        continue
                    source = other[len(block + "_without_") :]
                    w = values([r for r in wo_runs if r["truth_seed"] == seed], metric)
                    w = w[np.isfinite(w)]
                    if len(w) < 3:
                        continue
                    ci = bootstrap_interval((x, w), _share, confidence)
                    row["shares"][source] = (float(_share(x, w)), ci, len(w))
                rows.append(row)
    return rows


def _illustrates(run: dict) -> bool:
    return run["truth_seed"] == ILLUSTRATION_ROBOT


def illustration(blocks: dict[str, list[dict]], rules: dict[str, Rule]) -> dict:
    """The illustration robot's percentile in each metric of its population.

    Its own runs in each population (truth seed :data:`ILLUSTRATION_ROBOT`, the population's
    run seed: its homing and noise are that run's, not the figures' run seed 1).

    Returns:
        ``{rule id: (its value, its percentile [%], n)}``.
    """
    from scipy.stats import percentileofscore

    out = {}
    for rule in rules.values():
        runs = blocks.get(rule.population, [])
        mine = next((r.get(rule.metric) for r in runs if _illustrates(r)), None)
        v = values(runs, rule.metric)
        v = v[np.isfinite(v)]
        if mine is None or not len(v) or not math.isfinite(mine):
            continue
        out[rule.id] = (float(mine), float(percentileofscore(v, mine, kind="mean")), len(v))
    return out


def judge_population(
    blocks: dict[str, list[dict]], rules: dict[str, Rule], repeat: list, nees_numbers: dict
) -> dict:
    """Apply the criteria to a population's metrics: verdicts, sensitivities, illustration.

    Args:
        blocks: each block's runs with their metrics (:func:`collect`, or ``report.json``).
        rules: the criteria (:func:`~cdpr_twin.study.criteria.load_criteria`).
        repeat: the repetitions' rows (:func:`repeatability`).
        nees_numbers: the NEES summary (:func:`nees_summary`).
    """
    verdicts, sensitivity = [], []
    for rule in rules.values():
        verdicts.append(judge(rule, values(blocks.get(rule.population, []), rule.metric)))
        for block in rule.sensitivity:
            if block in blocks:
                sensitivity.append((rule, block, judge(rule, values(blocks[block], rule.metric))))
    return {
        "rules": rules,
        "blocks": blocks,
        "verdicts": verdicts,
        "sensitivity": sensitivity,
        "repeatability": repeat,
        "illustration": illustration(blocks, rules),
        "nees": nees_numbers,
    }


def population_report(out: Path, criteria: str | Path | None = None) -> dict:
    """The population's verdicts, sensitivities, repeatability and NEES.

    Args:
        out: the population campaign's directory (its table and ``runs/``).
        criteria: the criteria file (default: the shipped one).
    """
    rules = load_criteria() if criteria is None else load_criteria(criteria)
    confidence = next(iter(rules.values())).confidence
    blocks = collect(out, confidence)
    repeat = repeatability(blocks, confidence)
    nees_numbers = nees_summary(blocks.get("robots_open_loop", []), confidence)
    return judge_population(blocks, rules, repeat, nees_numbers)


def population_from_json(data: dict, criteria: str | Path | None = None) -> dict:
    """:func:`population_report` from ``report.json``'s numbers: the criteria applied anew."""
    rules = load_criteria() if criteria is None else load_criteria(criteria)
    return judge_population(data["metrics"], rules, data["repeatability"], data["nees"])


def nees_summary(runs: list[dict], confidence: float) -> dict:
    """The classical NEES test over the runs, and each axis's mean normalised squared error.

    ε̄ at each tick against its χ²(6N)/N interval; each axis's δ²/σ² is 1 for a consistent
    filter.
    """
    runs = [r for r in runs if "nees" in r]
    if not runs:
        return {}
    k = min(len(r["nees"]) for r in runs)
    eps = np.array([r["nees"][:k] for r in runs])
    low, high = nees_bounds(confidence, runs=len(runs))
    avg = eps.mean(axis=0)
    return {
        "runs": len(runs),
        "ticks": k,
        "bounds": (float(low), float(high)),
        "inside": float(np.mean((avg >= low) & (avg <= high))),
        "above": float(np.mean(avg > high)),
        "below": float(np.mean(avg < low)),
        "mean": float(np.mean(eps)),
        "axes": np.mean([r["nees_axes"] for r in runs], axis=0).tolist(),
    }


def population_json(pop: dict) -> dict:
    """The population's numbers for ``report.json``.

    Every run's metrics (not its NEES series), the repetitions, NEES; and, for a reader, the
    verdicts they gave (:func:`population_from_json` applies the criteria anew).
    """
    return {
        "metrics": {
            block: [{k: v for k, v in r.items() if k != "nees"} for r in runs]
            for block, runs in pop["blocks"].items()
        },
        "repeatability": pop["repeatability"],
        "nees": pop["nees"],
        "verdicts": [
            {
                "id": v.rule.id,
                "population": v.rule.population,
                "n": v.n,
                "k": v.k,
                "interval": list(v.interval),
                "verdict": v.verdict,
            }
            for v in pop["verdicts"]
        ],
    }
