"""Reproduce the paper's study in one command: runs, figures and a findings report.

The study (DESIGN §8): the open-loop experiment with all six estimators passive (Fig. 5), PBVS
with each estimator in the loop (Fig. 7), and the accuracy and repeatability campaign of §IV-D
(Fig. 8): 10 open-loop runs and 30 PBVS runs, 5 per estimator. One robot (the scenarios' truth
seed) throughout; each run draws its own sensor noise (run seed). The seed-1 runs are also the
runs of Fig. 5 and 7. Runs are independent processes, in parallel; a failed run is reported and
the others are kept.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from cdpr_twin import MODELS_DIR
from cdpr_twin.results import (
    ESTIMATOR_ORDER,
    MODEL_ESTIMATORS,
    image_noise_vs_distance,
    load_summary,
    load_timeseries,
    roughness,
    value_at,
)
from cdpr_twin.se3 import pose_from_vector

SCENARIOS_DIR = MODELS_DIR.parent / "scenarios"
OPEN_LOOP_RUNS = 10
PBVS_RUNS_PER_ESTIMATOR = 5


@dataclass(frozen=True)
class RunSpec:
    """One run of the study.

    Attributes:
        name: unique name (its output directory under ``runs/``).
        kind: ``"open_loop"`` or ``"pbvs"``.
        scenario: scenario file.
        seed: run seed (sensor noise).
        in_loop: estimator closing the loop (PBVS).
        duration: duration override [s], or ``None``.
        record_rrd: write a Rerun recording (the figure runs only).
    """

    name: str
    kind: str
    scenario: str
    seed: int
    in_loop: str | None = None
    duration: float | None = None
    record_rrd: bool = False


def plan(
    runs_scale: float = 1.0, duration: float | None = None, scenarios_dir: Path = SCENARIOS_DIR
) -> list[RunSpec]:
    """The runs of the study; ``runs_scale`` scales the repetition counts (at least one each)."""
    if not (math.isfinite(runs_scale) and runs_scale > 0):
        raise ValueError(f"--runs-scale must be > 0, got {runs_scale}")
    n_open = max(1, round(OPEN_LOOP_RUNS * runs_scale))
    n_pbvs = max(1, round(PBVS_RUNS_PER_ESTIMATOR * runs_scale))
    ol, pb = str(scenarios_dir / "paper_open_loop.toml"), str(scenarios_dir / "paper_pbvs.toml")
    specs = [
        RunSpec(f"open_loop_seed{k}", "open_loop", ol, k, None, duration, k == 1)
        for k in range(1, n_open + 1)
    ]
    specs += [
        RunSpec(f"pbvs_{name}_seed{k}", "pbvs", pb, k, name, duration, k == 1)
        for name in ESTIMATOR_ORDER
        for k in range(1, n_pbvs + 1)
    ]
    return specs


def _run_one(spec: RunSpec, runs_dir: str) -> dict:
    """Worker (a spawned process): run one spec; never raise, report instead."""
    from cdpr_twin.runner import run
    from cdpr_twin.scenario import load_scenario

    out = Path(runs_dir) / spec.name
    try:
        s = load_scenario(spec.scenario).with_overrides(
            seed=spec.seed, in_loop=spec.in_loop, duration=spec.duration
        )
        result = run(s, out, record_rrd=spec.record_rrd)
        return {
            **asdict(spec),
            "ok": True,
            "status": result.summary["status"],
            "wall_time_s": result.wall_time,
            "dir": str(out),
        }
    except Exception as exc:  # keep the others' results: this one is reported as failed
        return {
            **asdict(spec),
            "ok": False,
            "status": f"failed: {type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
            "dir": str(out),
        }


def run_study(
    specs: list[RunSpec],
    out: Path,
    workers: int,
    progress: Callable[[int, int, dict], None] | None = None,
) -> list[dict]:
    """Run every spec in ``workers`` spawned processes; returns one record per run."""
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    records = []
    # spawn: a forked child would inherit the parent's Rerun/EGL threads' locks
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [pool.submit(_run_one, s, str(runs_dir)) for s in specs]
        for done, fut in enumerate(as_completed(futures), 1):
            record = fut.result()
            records.append(record)
            if progress is not None:
                progress(done, len(specs), record)
    order = {s.name: i for i, s in enumerate(specs)}
    records.sort(key=lambda r: order[r["name"]])
    (out / "runs.json").write_text(json.dumps(records, indent=2) + "\n", encoding="utf-8")
    return records


# ---------------------------------------------------------------------------------- analysis


def _p1() -> np.ndarray:
    return pose_from_vector([0.284, -0.197, 0.08, 0, 0, 0])


def accuracy_at_p1(run_dir: Path, kind: str) -> dict | None:
    """Final platform error at p1 of one run, recomputed from its time series.

    Open loop: ground truth at t = 10 s (end of p0 → p1) against p1. PBVS: ground truth at the
    end of the run against p1. ``None`` when the run did not reach that time.
    """
    from cdpr_twin.se3 import pose_distances

    ts = load_timeseries(run_dir / "timeseries.csv")
    truth = ts.poses("true")
    if kind == "open_loop":
        if ts.t[-1] < 10.0 - 1e-6:
            return None
        row = int(np.argmin(np.abs(ts.t - 10.0)))
    else:
        row = len(ts.t) - 1
    dt, dr = pose_distances(truth[row : row + 1], _p1()[None])
    return {
        "time_s": float(ts.t[row]),
        "translation_m": float(dt[0]),
        "rotation_deg": float(np.degrees(dr[0])),
    }


def _model_physics(ts, scenario_file: Path) -> dict:
    """Why the model-based variants agree on ACROBOT: stretch and wrap along the run."""
    from cdpr_twin import kinematics as kin
    from cdpr_twin.scenario import load_scenario
    from cdpr_twin.sim import build_model, read_geometry

    geom = read_geometry(build_model(load_scenario(scenario_file).model.file))
    tau, l0 = ts.matrix("tension"), ts.matrix("length")
    stretch = np.abs(tau) * l0 / geom.es  # eq. 14 with τ(0) = 0
    T = ts.poses("true")
    wrap = np.array(
        [
            kin.cable_lengths(geom, Ti, "pulley") - kin.cable_lengths(geom, Ti)
            for Ti in T[:: max(1, len(T) // 200)]
        ]
    )
    return {
        "max_stretch_m": float(np.nanmax(stretch)),
        "wrap_min_m": float(wrap.min()),
        "wrap_max_m": float(wrap.max()),
        "wrap_change_max_m": float((wrap.max(axis=0) - wrap.min(axis=0)).max()),
    }


def _camera_tag_errors(scenario_file: Path) -> dict:
    """Magnitude of the drawn robot's camera-mount and tag-placement rotation errors."""
    from cdpr_twin.scenario import load_scenario

    dev = load_scenario(scenario_file).truth.draw()
    return {
        "camera_rotation_deg": float(np.degrees(np.linalg.norm(dev.camera_offset[3:]))),
        "camera_position_m": float(np.linalg.norm(dev.camera_offset[:3])),
        "tag_rotation_deg": float(np.degrees(np.linalg.norm(dev.tag_offset[3:]))),
        "tag_position_m": float(np.linalg.norm(dev.tag_offset[:3])),
    }


def analyse(out: Path, records: list[dict]) -> dict:
    """Every number of the report, from the runs' files. Writes ``report.json``."""
    ok = [r for r in records if r["ok"]]
    by_name = {r["name"]: Path(r["dir"]) for r in ok}
    rep: dict = {
        "runs": {
            "total": len(records),
            "ok": len(ok),
            "failed": [{"name": r["name"], "status": r["status"]} for r in records if not r["ok"]],
        }
    }
    # -- open loop (Fig. 5) --
    main_ol = by_name.get("open_loop_seed1")
    if main_ol is not None:
        ts = load_timeseries(main_ol / "timeseries.csv")
        summary = load_summary(main_ol / "summary.json")
        names = [n for n in ESTIMATOR_ORDER if ts.has(n)]
        ol: dict = {"estimators": {}}
        for n in names:
            dt, dr = ts.deviation(n)
            ol["estimators"][n] = {
                "max_translation_m": float(np.nanmax(dt)),
                "max_rotation_deg": float(np.degrees(np.nanmax(dr))),
                "final_translation_m": float(dt[-1]),
                "final_rotation_deg": float(np.degrees(dr[-1])),
                "roughness_m": roughness(ts, n),
            }
        if ts.t[-1] >= 10.0 - 1e-6:
            miss_t, miss_r = ts.deviation("true", "plan")
            ol["miss_at_p1"] = {
                "translation_m": value_at(ts, 10.0, miss_t),
                "rotation_deg": float(np.degrees(value_at(ts, 10.0, miss_r))),
            }
            ol["follow_plan"] = {}
            for n in names:
                vs_plan, _ = ts.deviation(n, "plan")
                vs_truth, _ = ts.deviation(n)
                ol["follow_plan"][n] = {
                    "vs_plan_m": value_at(ts, 10.0, vs_plan),
                    "vs_truth_m": value_at(ts, 10.0, vs_truth),
                }
        models = [n for n in MODEL_ESTIMATORS if n in names]
        if models:
            P = np.array([ts.poses(n)[:, :3, 3] for n in models])
            pairwise = max(
                float(np.nanmax(np.linalg.norm(P[i] - P[j], axis=1)))
                for i in range(len(models))
                for j in range(i + 1, len(models))
            )
            ol["model_variants"] = {
                "max_pairwise_difference_m": pairwise,
                "max_deviation_m": max(ol["estimators"][n]["max_translation_m"] for n in models),
                **_model_physics(ts, Path(summary["source"])),
            }
        if "image" in names:
            ol["image_distance"] = image_noise_vs_distance(ts)
        rep["open_loop"] = ol
    # -- PBVS, each estimator in the loop (Fig. 7) --
    pbvs = {}
    for n in ESTIMATOR_ORDER:
        d = by_name.get(f"pbvs_{n}_seed1")
        if d is None:
            continue
        ts = load_timeseries(d / "timeseries.csv")
        s = load_summary(d / "summary.json")
        dt, dr = ts.deviation(n)
        pbvs[n] = {
            "status": s["status"],
            "max_translation_m": float(np.nanmax(dt)),
            "max_rotation_deg": float(np.degrees(np.nanmax(dr))),
            "roughness_m": roughness(ts, n),
            "final_tag_error": s.get("pbvs", {}).get("final_tag_error"),
            "others_roughness_m": {
                m: roughness(ts, m) for m in ESTIMATOR_ORDER if ts.has(m) and m != n
            },
        }
    rep["pbvs"] = pbvs
    # -- accuracy and repeatability at p1 (Fig. 8) --
    acc: dict[str, dict[str, list[float]]] = {}
    for r in ok:
        a = accuracy_at_p1(Path(r["dir"]), r["kind"])
        if a is None or (r["kind"] == "pbvs" and r["status"] != "converged"):
            continue
        for key in (
            "open loop" if r["kind"] == "open_loop" else "PBVS (all)",
            None if r["kind"] == "open_loop" else f"PBVS {r['in_loop']}",
        ):
            if key is None:
                continue
            g = acc.setdefault(key, {"translation_m": [], "rotation_deg": []})
            g["translation_m"].append(a["translation_m"])
            g["rotation_deg"].append(a["rotation_deg"])
    rep["accuracy"] = acc
    if "open loop" in acc and "PBVS (all)" in acc:
        rep["ratios"] = {
            k: float(np.mean(acc["open loop"][k]) / np.mean(acc["PBVS (all)"][k]))
            for k in ("translation_m", "rotation_deg")
        }
    rep["robot"] = _camera_tag_errors(SCENARIOS_DIR / "paper_pbvs.toml")
    rep["findings"] = _findings(rep)
    (out / "report.json").write_text(json.dumps(rep, indent=2) + "\n", encoding="utf-8")
    return rep


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else ("agrees" if ok else "disagrees")


def _findings(rep: dict) -> list[dict]:
    """Each finding: the paper's claim, the twin's numbers, a computed verdict, and why."""
    out = []
    ol, pbvs = rep.get("open_loop", {}), rep.get("pbvs", {})
    miss = ol.get("miss_at_p1")
    if miss:
        m = miss["translation_m"]
        out.append(
            {
                "finding": "open-loop error at p1 ≈ 1 cm (goal 0.5–2 cm)",
                "paper": "≈ 1 cm",
                "twin": f"{m * 100:.2f} cm / {miss['rotation_deg']:.2f}°",
                "verdict": _verdict(0.005 <= m <= 0.02),
                "why": "Â uses the nominal geometry; the robot's exit and anchor points differ "
                "by ~1 cm, so integrating l̇ = Â ᵇv_p lands elsewhere.",
            }
        )
    fp = ol.get("follow_plan")
    if fp and miss:
        names = [n for n in fp if n != "image"]
        worst = max(fp[n]["vs_plan_m"] for n in names)
        out.append(
            {
                "finding": "control and model estimates follow the plan, not the robot",
                "paper": "estimates ≈ p1 while the MP is ≈ 1 cm away",
                "twin": f"at t = 10 s: ≤ {worst * 1e3:.2f} mm from the plan, robot "
                f"{miss['translation_m'] * 1e3:.1f} mm from it",
                "verdict": _verdict(worst < 0.25 * miss["translation_m"]),
                "why": "the control estimate integrates the commanded (planned) twist; the "
                "model-based ones invert the same nominal model the plan was made "
                "with, from encoder lengths that follow the plan exactly.",
            }
        )
    if ol.get("estimators") and "image" in ol["estimators"]:
        r_img = ol["estimators"]["image"]["roughness_m"]
        r_oth = max(v["roughness_m"] for n, v in ol["estimators"].items() if n != "image")
        pb = pbvs.get("control")
        pb_ok = (
            None
            if pb is None or "image" not in pb["others_roughness_m"]
            else (
                pb["others_roughness_m"]["image"]
                > max(v for n, v in pb["others_roughness_m"].items() if n != "image")
            )
        )
        ok = r_img > r_oth and (pb_ok is None or pb_ok)
        out.append(
            {
                "finding": "image-based estimate is the noisiest",
                "paper": "noisiest with both controllers",
                "twin": f"tick-to-tick RMS {r_img * 1e3:.3f} mm vs ≤ {r_oth * 1e3:.3f} mm for "
                "the others (open loop)",
                "verdict": _verdict(ok),
                "why": "it rests on 4 tag corners; a 4 cm tag at 0.1–0.35 m gives tilt "
                "errors of tenths of a degree, i.e. millimetres at the platform.",
            }
        )
    imd = ol.get("image_distance")
    if imd:
        ok = imd["far_noise_m"] > imd["near_noise_m"] and imd["spearman"] > 0
        out.append(
            {
                "finding": "image-based gets noisier farther from the tag",
                "paper": "good near the tag (t = 8–12 s), highly noisy far",
                "twin": f"tick-to-tick RMS {imd['near_noise_m'] * 1e3:.3f} mm at "
                f"{imd['near_distance_m']:.2f} m vs {imd['far_noise_m'] * 1e3:.3f} mm "
                f"at {imd['far_distance_m']:.2f} m (Spearman {imd['spearman']:.2f}); "
                f"mean deviation {imd['near_mean_deviation_m'] * 1e3:.2f} mm near vs "
                f"{imd['far_mean_deviation_m'] * 1e3:.2f} mm far",
                "verdict": _verdict(ok),
                "why": "the tag shrinks in the image and its corners carry less pose "
                "information (tilt observability falls as (s/2Z)²). The mean "
                "deviation is a different story: it is a bias from the camera-mount "
                "error and the reference taken at p0, and grows with the motion "
                "since p0, which brings the camera near the tag.",
            }
        )
    mv = ol.get("model_variants")
    if mv:
        ok = mv["max_pairwise_difference_m"] < 0.1 * mv["max_deviation_m"]
        out.append(
            {
                "finding": "the four model-based variants are nearly identical on ACROBOT",
                "paper": "almost the same output",
                "twin": "max difference between variants "
                f"{mv['max_pairwise_difference_m'] * 1e3:.2f} mm vs their deviation from truth "
                f"up to {mv['max_deviation_m'] * 1e3:.1f} mm",
                "verdict": _verdict(ok),
                "why": f"stretch τ·l/(E·S) is at most {mv['max_stretch_m'] * 1e6:.0f} µm and "
                f"the pulley wrap (l_pulley − l_straight, "
                f"{mv['wrap_min_m'] * 1e3:.2f}–{mv['wrap_max_m'] * 1e3:.2f} mm) changes "
                f"by at most {mv['wrap_change_max_m'] * 1e3:.2f} mm along the run, "
                "against centimetre geometry errors.",
            }
        )
    if pbvs:
        maxes = {n: v["max_translation_m"] for n, v in pbvs.items()}
        best = min(maxes, key=maxes.get)
        why = (
            "in closed loop the servo corrects the robot's pose, and the control estimate "
            "drifts only with the mismatch between commanded and achieved twists (as "
            "model-based ones drift with model error)."
        )
        if best == "image":
            others = [n for n in maxes if n != "image"]
            why += (
                " Here the image-based estimate is best instead: the twin's camera is ideal"
                " (no pixel noise, blur, distortion or intrinsics error) and PBVS brings it "
                "within 9 cm of the tag, where 4 sub-pixel corners give sub-millimetre "
                "poses; the real camera's noise, which made Est. 2 the noisiest on ACROBOT,"
                " is not modelled. Among the others, "
                f"{min(others, key=maxes.get)} is best."
            )
        out.append(
            {
                "finding": "control-based estimate is the best with PBVS",
                "paper": "control ≤ 0.9 cm / 2°, best of all",
                "twin": ", ".join(f"{n} {v * 1e3:.1f} mm" for n, v in maxes.items()),
                "verdict": _verdict(best == "control" if "control" in maxes else None),
                "why": why,
            }
        )
    acc = rep.get("accuracy", {})
    if "open loop" in acc and "PBVS (all)" in acc:
        spreads = {k: float(np.std(acc[k]["translation_m"])) for k in ("open loop", "PBVS (all)")}
        counts = {k: len(acc[k]["translation_m"]) for k in spreads}
        out.append(
            {
                "finding": "repeatability: spread of the final pose at p1 over repetitions",
                "paper": "10 open-loop and 30 PBVS runs with a visible spread (Fig. 8)",
                "twin": f"std {spreads['open loop'] * 1e6:.1f} µm over {counts['open loop']} "
                f"open-loop runs, {spreads['PBVS (all)'] * 1e6:.1f} µm over "
                f"{counts['PBVS (all)']} PBVS runs",
                "verdict": "n/a",
                "why": "the paper gives no number. In the twin the only thing that changes between "
                "repetitions is the tension-sensor noise: the open-loop robot never reads its "
                "sensors, and PBVS converges onto a noise-free rendered image, so runs repeat "
                "to micrometres. The real robot's spread comes from what the twin does not "
                "model: camera noise, winch and drum errors, friction, cable creep.",
            }
        )
    ratios, robot = rep.get("ratios"), rep.get("robot", {})
    if ratios:
        acc = rep["accuracy"]
        pb_rot = float(np.mean(acc["PBVS (all)"]["rotation_deg"]))
        for key, paper_ratio, unit in (
            ("translation_m", 5.0, "translation"),
            ("rotation_deg", 4.0, "rotation"),
        ):
            ok = ratios[key] >= 3.0
            why = (
                "PBVS servoes the camera onto the tag, so at convergence only camera-mount, "
                "tag-placement and detection errors remain; open loop carries the full "
                "geometry error."
            )
            if not ok and key == "rotation_deg":
                why += (
                    f" Here this robot's camera mount is off by "
                    f"{robot['camera_rotation_deg']:.2f}° and its tag by "
                    f"{robot['tag_rotation_deg']:.2f}°: PBVS ends {pb_rot:.2f}° from p1 "
                    "however well it converges, while its open-loop rotation error is small;"
                    " the paper's robot had a better-calibrated camera and tag relative to p1."
                )
            out.append(
                {
                    "finding": f"PBVS more accurate than open loop at p1 ({unit})",
                    "paper": f"{paper_ratio:.0f}×",
                    "twin": f"{ratios[key]:.1f}×",
                    "verdict": _verdict(ok),
                    "why": why,
                }
            )
    return out


# ---------------------------------------------------------------------------------- outputs


def make_figures(out: Path, rep: dict, records: list[dict]) -> list[Path]:
    """Fig. 5a/5b, 7a/7b and 8 into ``out``."""
    from cdpr_twin import figures

    by_name = {r["name"]: Path(r["dir"]) for r in records if r["ok"]}
    paths: list[Path] = []
    if "open_loop_seed1" in by_name:
        ts = load_timeseries(by_name["open_loop_seed1"] / "timeseries.csv")
        paths += figures.open_loop_figures(ts, out, marks=(10.0, 15.0))
    runs = {
        n: load_timeseries(by_name[f"pbvs_{n}_seed1"] / "timeseries.csv")
        for n in ESTIMATOR_ORDER
        if f"pbvs_{n}_seed1" in by_name
    }
    if runs:
        paths += figures.pbvs_figures(runs, out)
    if rep.get("accuracy"):
        paths.append(figures.accuracy_bars(rep["accuracy"], out / "fig8.png"))
    return paths


def _mm(v: float) -> str:
    return f"{v * 1e3:.2f} mm"


def write_report(out: Path, rep: dict, figures: list[Path], wall_time_s: float) -> Path:
    """``report.md``: the paper's numbers beside the twin's, and the findings with verdicts."""
    ol, pbvs = rep.get("open_loop", {}), rep.get("pbvs", {})
    lines = [
        "# cdpr-twin: the paper's study, reproduced",
        "",
        f"{rep['runs']['ok']} of {rep['runs']['total']} runs completed "
        f"({wall_time_s / 60:.1f} min). Every number below is computed from the runs' "
        "`timeseries.csv` and `summary.json` files (also in `report.json`).",
        "",
    ]
    if rep["runs"]["failed"]:
        lines += (
            ["Failed runs:", ""]
            + [f"- `{f['name']}`: {f['status']}" for f in rep["runs"]["failed"]]
            + [""]
        )
    lines += [
        "## Findings",
        "",
        "| finding | paper | twin | verdict | why |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {f['finding']} | {f['paper']} | {f['twin']} | **{f['verdict']}** | {f['why']} |"
        for f in rep["findings"]
    ]
    lines += [
        "",
        "## The paper's numbers beside the twin's",
        "",
        "| quantity | paper | twin |",
        "|---|---|---|",
    ]
    e = ol.get("estimators", {})
    if "control" in e:
        c = e["control"]
        lines.append(
            f"| open loop, control-based: max deviation | 1.4 cm / 1.6° | "
            f"{c['max_translation_m'] * 100:.2f} cm / {c['max_rotation_deg']:.2f}° |"
        )
        lines.append(
            f"| open loop, control-based: final deviation | 1.3 mm / 0.55° | "
            f"{_mm(c['final_translation_m'])} / {c['final_rotation_deg']:.2f}° |"
        )
    models = [n for n in MODEL_ESTIMATORS if n in e]
    if models:
        worst = max(e[n]["max_translation_m"] for n in models)
        lines.append(
            f"| open loop, model-based: max translational deviation | 1.21 cm | "
            f"{worst * 100:.2f} cm |"
        )
    if "miss_at_p1" in ol:
        lines.append(
            f"| open loop: MP error at p1 | ≈ 1 cm | "
            f"{ol['miss_at_p1']['translation_m'] * 100:.2f} cm |"
        )
    paper_pbvs = {
        "control": "≤ 0.9 cm / 2°",
        "model_simple": "≤ 1.29 cm / 2°",
        "model_elastic": "≤ 1.29 cm / 2°",
        "model_pulley": "≤ 1.56 cm",
        "model_elastic_pulley": "≤ 1.56 cm",
        "image": "noisiest",
    }
    for n, v in pbvs.items():
        lines.append(
            f"| PBVS, {n} in the loop: max deviation | {paper_pbvs[n]} | "
            f"{v['max_translation_m'] * 100:.2f} cm / {v['max_rotation_deg']:.2f}° |"
        )
    if "ratios" in rep:
        lines.append(
            f"| PBVS / open-loop accuracy at p1, translation | 5× | "
            f"{rep['ratios']['translation_m']:.1f}× |"
        )
        lines.append(
            f"| PBVS / open-loop accuracy at p1, rotation | 4× | "
            f"{rep['ratios']['rotation_deg']:.1f}× |"
        )
    if rep.get("accuracy"):
        lines += [
            "",
            "## Accuracy at p1 (Fig. 8)",
            "",
            "| runs | n | translation mean ± std | rotation mean ± std |",
            "|---|---|---|---|",
        ]
        for k, g in rep["accuracy"].items():
            t, r = np.array(g["translation_m"]), np.array(g["rotation_deg"])
            lines.append(
                f"| {k} | {len(t)} | {_mm(t.mean())} ± {_mm(t.std())} | "
                f"{r.mean():.3f}° ± {r.std():.3f}° |"
            )
    lines += ["", "## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def reproduce(
    out: Path,
    workers: int | None = None,
    runs_scale: float = 1.0,
    duration: float | None = None,
    progress: Callable[[int, int, dict], None] | None = None,
) -> dict:
    """Run the study and write ``runs/``, ``runs.json``, figures, ``report.json``, ``report.md``.

    Returns:
        The report numbers (as in ``report.json``), plus ``"wall_time_s"``.
    """
    import time

    workers = workers or max(1, multiprocessing.cpu_count())
    specs = plan(runs_scale, duration)
    start = time.perf_counter()
    records = run_study(specs, out, workers, progress)
    rep = analyse(out, records)
    figs = make_figures(out, rep, records)
    wall = time.perf_counter() - start
    write_report(out, rep, figs, wall)
    return {**rep, "wall_time_s": wall}
