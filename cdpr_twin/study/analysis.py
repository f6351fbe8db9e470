"""Every number of the study's report, computed from the runs' files only.

Nothing about the experiment is assumed here: p1 and the time the open-loop plan reaches it
come from the open-loop run's ``summary.json`` (its first segment end), the estimators from each
run's ``timeseries.csv``, the robot from the scenario file the runs were made with.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_twin.files.transaction import write_json_atomic
from cdpr_twin.math.se3 import pose_distance, pose_from_vector
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.study.findings import evaluate
from cdpr_twin.study.plan import PBVS_SCENARIO
from cdpr_twin.study.repeatability import PBVS_CONVERGED, is_main, repetition_rms, spread
from cdpr_twin.study.results import (
    image_noise_vs_distance,
    load_summary,
    model_estimators,
    ordered_estimators,
    roughness,
    value_at,
)
from cdpr_twin.study.robot_numbers import model_physics, payloads, robot_errors


@dataclass(frozen=True, eq=False)
class SegmentEnd:
    """Where an open-loop plan reaches a waypoint.

    Attributes:
        time_s: time of the tick at the segment's end [s].
        waypoint: the waypoint as written in ``summary.json``: [x, y, z (m), rx, ry, rz (deg)].
    """

    time_s: float
    waypoint: tuple[float, ...]

    @property
    def T_waypoint(self) -> np.ndarray:
        """(4, 4) the waypoint's pose."""
        return pose_from_vector(self.waypoint)


def segment_ends(summary: dict) -> list[SegmentEnd]:
    """The segment ends an open-loop run's ``summary.json`` lists (p1 first), in time order."""
    return [
        SegmentEnd(float(e["time_s"]), tuple(float(v) for v in e["waypoint"]))
        for e in summary.get("segment_ends", [])
    ]


def figure_runs(records: list[dict]) -> tuple[Path | None, dict[str, Path]]:
    """The runs of Fig. 5 and 7 (seed 1): the open-loop run, and each PBVS run by estimator.

    Returns:
        ``(open-loop run directory or None, {in-loop estimator: PBVS run directory})``, the
        estimators in display order; failed runs are left out.
    """
    ok = [r for r in records if r["ok"] and r["seed"] == 1 and is_main(r)]
    open_loop = next((Path(r["dir"]) for r in ok if r["kind"] == "open_loop"), None)
    pbvs = {r["in_loop"]: Path(r["dir"]) for r in ok if r["kind"] == "pbvs"}
    return open_loop, {n: pbvs[n] for n in ordered_estimators(pbvs)}


def reference_p1(records: list[dict]) -> SegmentEnd | None:
    """p1: the first segment end of the (first successful) open-loop run, or ``None``."""
    for r in records:
        if r["ok"] and r["kind"] == "open_loop":
            ends = segment_ends(load_summary(Path(r["dir"]) / "summary.json"))
            if ends:
                return ends[0]
    return None


def accuracy_at_p1(run_dir: Path, kind: str, p1: np.ndarray | None = None) -> dict | None:
    """Final platform error at p1 of one run, recomputed from its time series.

    Open loop: ground truth at the run's first segment end against its first waypoint (p1).
    PBVS: ground truth at the end of the run against ``p1`` or, when ``None``, against the run's
    own ``goal_pose``. ``None`` when the run has no such time or pose.
    """
    summary = load_summary(run_dir / "summary.json")
    ts = Timeseries.load(run_dir / "timeseries.csv")
    if kind == "open_loop":
        ends = segment_ends(summary)
        if not ends:
            return None
        row, reference = int(np.argmin(np.abs(ts.t - ends[0].time_s))), ends[0].T_waypoint
    else:
        if p1 is None and summary.get("goal_pose") is None:
            return None
        reference = p1 if p1 is not None else pose_from_vector(summary["goal_pose"])
        row = len(ts.t) - 1
    dt, dr = pose_distance(ts.poses("true")[row : row + 1], reference[None])
    return {
        "time_s": float(ts.t[row]),
        "translation_m": float(dt[0]),
        "rotation_deg": float(np.degrees(dr[0])),
    }


def _estimator_deviations(ts: Timeseries, names: tuple[str, ...]) -> dict:
    """Each estimator's max and final deviation from ground truth, and its roughness."""
    out = {}
    for n in names:
        dt, dr = ts.deviation(n)
        out[n] = {
            "max_translation_m": float(np.nanmax(dt)),
            "max_rotation_deg": float(np.degrees(np.nanmax(dr))),
            "final_translation_m": float(dt[-1]),
            "final_rotation_deg": float(np.degrees(dr[-1])),
            "roughness_m": roughness(ts, n),
            **_rms(dt, dr),
        }
    return out


def _rms(dt: np.ndarray, dr: np.ndarray) -> dict:
    """RMS over the run of a translational [m] and rotational [rad] deviation."""
    return {
        "rms_translation_m": float(np.sqrt(np.nanmean(dt**2))),
        "rms_rotation_deg": float(np.degrees(np.sqrt(np.nanmean(dr**2)))),
    }


def _at_p1(ts: Timeseries, names: tuple[str, ...], t1: float) -> dict:
    """The robot's miss of the plan at p1 (time t1); each estimate's distance to plan and truth."""
    miss_t, miss_r = ts.deviation("true", "plan")
    follow = {}
    for n in names:
        vs_plan, _ = ts.deviation(n, "plan")
        vs_truth, _ = ts.deviation(n)
        follow[n] = {
            "vs_plan_m": value_at(ts, t1, vs_plan),
            "vs_truth_m": value_at(ts, t1, vs_truth),
        }
    miss = {
        "translation_m": value_at(ts, t1, miss_t),
        "rotation_deg": float(np.degrees(value_at(ts, t1, miss_r))),
        "time_s": t1,
    }
    return {"miss_at_p1": miss, "follow_plan": follow}


def _model_variants(ts: Timeseries, models: tuple[str, ...], ol: dict, source: Path) -> dict:
    """How far apart the model-based estimates are, against their deviation from truth."""
    P = np.array([ts.poses(n)[:, :3, 3] for n in models])
    pairwise = max(
        float(np.nanmax(np.linalg.norm(P[i] - P[j], axis=1)))
        for i in range(len(models))
        for j in range(i + 1, len(models))
    )
    return {
        "n_variants": len(models),
        "max_pairwise_difference_m": pairwise,
        "max_deviation_m": max(ol["estimators"][n]["max_translation_m"] for n in models),
        **model_physics(ts, source),
    }


def analyse_open_loop(run_dir: Path) -> dict:
    """Fig. 5 numbers of one open-loop run: deviations, the miss at p1, the model variants."""
    ts = Timeseries.load(run_dir / "timeseries.csv")
    summary = load_summary(run_dir / "summary.json")
    names = ordered_estimators(ts.estimator_names)
    ol: dict = {"estimators": _estimator_deviations(ts, names)}
    ends = segment_ends(summary)
    if ends:
        ol.update(_at_p1(ts, names, ends[0].time_s))
    models = model_estimators(names)
    if len(models) > 1:
        ol["model_variants"] = _model_variants(ts, models, ol, Path(summary["source"]))
    if "image" in names:
        ol["image_distance"] = image_noise_vs_distance(ts)
    return ol


def analyse_pbvs(run_dir: Path, in_loop: str) -> dict:
    """Fig. 7 numbers of one PBVS run: the in-loop estimate's deviation, the others' noise."""
    ts = Timeseries.load(run_dir / "timeseries.csv")
    s = load_summary(run_dir / "summary.json")
    dt, dr = ts.deviation(in_loop)
    return {
        "status": s["status"],
        "max_translation_m": float(np.nanmax(dt)),
        "max_rotation_deg": float(np.degrees(np.nanmax(dr))),
        "roughness_m": roughness(ts, in_loop),
        "final_tag_error": s.get("pbvs", {}).get("final_tag_error"),
        **_rms(dt, dr),
        "others_roughness_m": {
            m: roughness(ts, m) for m in ordered_estimators(ts.estimator_names) if m != in_loop
        },
        "others_rms": {
            m: _rms(*ts.deviation(m))
            for m in ordered_estimators(ts.estimator_names)
            if m != in_loop
        },
        **_jumps(ts, [m for m in ordered_estimators(ts.estimator_names) if m != in_loop]),
    }


def _jumps(ts: Timeseries, names: list[str], start_s: float = 0.5) -> dict:
    """Each estimate's largest tick-to-tick change [m] and its time, and its later roughness.

    The later roughness is the RMS change after the first ``start_s`` seconds: what the
    roughness is without the start transient.
    """
    jumps, late = {}, {}
    for n in names:
        dt, _ = ts.deviation(n)
        d = np.abs(np.diff(dt))
        ok = np.isfinite(d)
        if not ok.any():
            continue
        k = int(np.nanargmax(d))
        jumps[n] = (float(d[k]), float(ts.t[k + 1]))
        after = d[ok & (ts.t[1:] > start_s)]
        late[n] = float(np.sqrt(np.mean(after**2))) if len(after) else float("nan")
    return {"others_max_jump": jumps, "others_roughness_after_start_m": late}


def _accuracy(ok: list[dict], p1: SegmentEnd | None) -> dict[str, dict[str, list[float]]]:
    """Fig. 8: final error at p1 per group (open loop, all PBVS, PBVS per in-loop estimator)."""
    acc: dict[str, dict[str, list[float]]] = {}
    for r in ok:
        if not is_main(r) or (r["kind"] == "pbvs" and r["status"] != PBVS_CONVERGED):
            continue
        a = accuracy_at_p1(Path(r["dir"]), r["kind"], None if p1 is None else p1.T_waypoint)
        if a is None:
            continue
        keys = ["open loop"] if r["kind"] == "open_loop" else ["PBVS (all)", f"PBVS {r['in_loop']}"]
        for key in keys:
            g = acc.setdefault(key, {"translation_m": [], "rotation_deg": []})
            g["translation_m"].append(a["translation_m"])
            g["rotation_deg"].append(a["rotation_deg"])
    return acc


def _robot_scenario(records: list[dict]) -> str | Path:
    """The scenario file the runs' robot is drawn from (PBVS first: the camera matters)."""
    for kind in ("pbvs", "open_loop"):
        for r in records:
            if r["kind"] == kind:
                return r["scenario"]
    return PBVS_SCENARIO


def _realism(scenario_file: str | Path) -> tuple[dict, str]:
    """The runs' realism profile (JSON-ready: ``inf`` → ``None``) and the PBVS goal option."""
    from cdpr_twin.scenario.loading import load_scenario

    s = load_scenario(scenario_file)

    def clean(v):
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return None if isinstance(v, float) and not np.isfinite(v) else v

    goal = getattr(s.controller.options, "goal", "nominal")
    return clean(dataclasses.asdict(s.realism)), goal


def analyse(out: Path, records: list[dict]) -> dict:
    """Every number of the report, from the runs' files. Writes ``report.json`` (whole).

    Args:
        out: the study's output directory.
        records: the runs, as :func:`cdpr_twin.study.run_study` returns them, or as
            ``runs.json`` holds them (each run's directory relative to ``out``).
    """
    from cdpr_twin.study.plan import with_dirs_in

    records = with_dirs_in(out, records)
    ok = [r for r in records if r["ok"]]
    rep: dict = {
        "runs": {
            "total": len(records),
            "ok": len(ok),
            "failed": [{"name": r["name"], "status": r["status"]} for r in records if not r["ok"]],
        }
    }
    p1 = reference_p1(records)
    if p1 is not None:
        rep["p1"] = {"time_s": p1.time_s, "waypoint": list(p1.waypoint)}
    main_ol, main_pbvs = figure_runs(records)
    if main_ol is not None:
        rep["open_loop"] = analyse_open_loop(main_ol)
    rep["pbvs"] = {n: analyse_pbvs(d, n) for n, d in main_pbvs.items()}
    acc = _accuracy(ok, p1)
    rep["accuracy"] = acc
    if "open loop" in acc and "PBVS (all)" in acc:
        rep["ratios"] = {
            k: float(np.mean(acc["open loop"][k]) / np.mean(acc["PBVS (all)"][k]))
            for k in ("translation_m", "rotation_deg")
        }
    rep["spread"] = spread(ok, accuracy_at_p1, None if p1 is None else p1.T_waypoint)
    rep["repetition_rms"] = repetition_rms(ok)
    rep["robot"] = {**robot_errors(_robot_scenario(records)), "payload_kg": payloads(records)}
    rep["realism"], rep["pbvs_goal"] = _realism(_robot_scenario(records))
    rep["findings"] = evaluate(rep)
    write_json_atomic(out / "report.json", rep)
    return rep
