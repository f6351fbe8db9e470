"""Repeatability (Fig. 8's spread) and where it comes from, and the PBVS goal two ways.

The decomposition repeats the open-loop runs and the control-in-the-loop PBVS runs with one
per-run source of variation switched off at a time (:data:`cdpr_twin.robot.realism.RUN_SOURCES`).
A source's share of the variance is 1 − Var(without it) / Var(all): the part of the spread that
disappears with it (sampling noise can make it slightly negative or push the shares' sum past
1 when the sources interact).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cdpr_twin.run.metrics import sample_std

PBVS_CONVERGED = "converged"
"""The status of a PBVS run that reached its goal (only those count for accuracy)."""


def is_main(record: dict) -> bool:
    """Whether a run belongs to the main campaign (not a decomposition or other-goal run)."""
    return not record.get("without") and not record.get("goal")


def _final_errors(records: list[dict], accuracy_at_p1, p1) -> dict[str, list[dict]]:
    """Final errors at p1 by campaign key ``(kind, group)``, converged PBVS runs only."""
    out: dict[str, list[dict]] = {}
    for r in records:
        if not r["ok"] or (r["kind"] == "pbvs" and r["status"] != PBVS_CONVERGED):
            continue
        if r["kind"] == "pbvs" and r.get("in_loop") != "control":
            continue
        a = accuracy_at_p1(Path(r["dir"]), r["kind"], p1)
        if a is None:
            continue
        group = "all"
        if r.get("without"):
            group = "without " + "+".join(r["without"])
        elif r.get("goal"):
            group = f"goal {r['goal']}"
        kind = "open loop" if r["kind"] == "open_loop" else "PBVS control"
        out.setdefault(f"{kind}|{group}", []).append(a)
    return out


def _stats(values: list[dict]) -> dict:
    t = np.array([v["translation_m"] for v in values])
    r = np.array([v["rotation_deg"] for v in values])
    return {
        "n": len(t),
        "mean_translation_m": float(t.mean()),
        "std_translation_m": sample_std(t),
        "mean_rotation_deg": float(r.mean()),
        "std_rotation_deg": sample_std(r),
    }


def spread(records: list[dict], accuracy_at_p1, p1) -> dict:
    """The spread of the final pose at p1 per controller, with each source's variance share.

    Args:
        records: every run (``runs.json``).
        accuracy_at_p1: ``accuracy_at_p1(run_dir, kind, p1) -> dict | None``.
        p1: (4, 4) the reference pose, or ``None`` (each run's own goal).

    Returns:
        ``{controller: {"all": stats, "without <source>": stats + variance_share…}}``.
    """
    groups = _final_errors(records, accuracy_at_p1, p1)
    out: dict[str, dict] = {}
    for key, values in sorted(groups.items()):
        kind, group = key.split("|")
        out.setdefault(kind, {})[group] = _stats(values)
    for g in out.values():
        base = g.get("all")
        if base is None or base["n"] < 2:
            continue
        for name, st in g.items():
            if name.startswith("without ") and st["n"] > 1:
                for q in ("translation_m", "rotation_deg"):
                    v_all, v_wo = base[f"std_{q}"] ** 2, st[f"std_{q}"] ** 2
                    st[f"variance_share_{q}"] = 1.0 - v_wo / v_all if v_all > 0 else None
    return out


def repetition_rms(records: list[dict]) -> dict[str, dict[str, dict]]:
    """Each estimator's RMS deviation over all repetitions of an experiment, not one run's.

    A run's RMS deviation depends on its draws (homing offset, noise); the RMS over the
    repetitions' runs, √(mean of each run's RMS²), is what a user of the estimator should
    expect. Experiments: open loop (passive estimators) and PBVS with control in the loop (the
    others passive beside it, converged runs only, as for the spread), main campaign runs only
    (decomposition runs switch sources off).

    Returns:
        ``{experiment: {estimator: {"n", "rms_translation_m", "rms_rotation_deg"}}}``.
    """
    runs: dict[str, list[dict]] = {}
    for r in records:
        if not (r["ok"] and is_main(r)):
            continue
        if r["kind"] == "pbvs" and (r.get("in_loop") != "control" or r["status"] != PBVS_CONVERGED):
            continue
        summary = Path(r["dir"]) / "summary.json"
        if not summary.is_file():
            continue
        key = "open loop" if r["kind"] == "open_loop" else "PBVS (control in the loop)"
        runs.setdefault(key, []).append(json.loads(summary.read_text("utf-8"))["estimators"])
    out: dict[str, dict[str, dict]] = {}
    for key, est in runs.items():
        for name in est[0]:
            rows = [e[name] for e in est if name in e and "rms_translation_m" in e[name]]
            if rows:
                out.setdefault(key, {})[name] = {
                    "n": len(rows),
                    "rms_translation_m": _quadratic_mean(r["rms_translation_m"] for r in rows),
                    "rms_rotation_deg": _quadratic_mean(r["rms_rotation_deg"] for r in rows),
                }
    return out


def _quadratic_mean(values) -> float:
    v = np.fromiter(values, dtype=float)
    return float(np.sqrt(np.mean(v**2)))


def several_runs(rms: dict[str, dict[str, dict]], name: str) -> dict[str, dict[str, dict]]:
    """The experiments of :func:`repetition_rms` with ``name`` and another, over several runs.

    One run's RMS over the repetitions is that run's own: such an experiment is left out.
    """
    return {exp: t for exp, t in rms.items() if name in t and len(t) > 1 and t[name]["n"] > 1}
