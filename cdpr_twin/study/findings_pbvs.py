"""The paper's findings about PBVS, repeatability and the fused filter (see :mod:`.findings`)."""

from __future__ import annotations

import numpy as np

from cdpr_twin.run.metrics import sample_std
from cdpr_twin.study.verdicts import Finding, verdict


def control_best_with_pbvs(rep: dict) -> Finding | None:
    """With PBVS, the in-loop control-based estimate deviates least from the truth."""
    pbvs = rep.get("pbvs", {})
    if not pbvs:
        return None
    maxes = {n: v["max_translation_m"] for n, v in pbvs.items()}
    best = min(maxes, key=maxes.get)
    why = (
        "in closed loop the servo corrects the robot's pose, and the control estimate "
        "drifts only with the mismatch between commanded and achieved twists (as "
        "model-based ones drift with model error)."
    )
    others = [n for n in maxes if n != "image"]
    ideal_camera = not rep.get("realism", {}).get("camera", {}).get("noise", False)
    if best == "image" and others and ideal_camera:
        why += (
            " Here the image-based estimate is best instead: the twin's camera is ideal"
            " (no pixel noise, blur, distortion or intrinsics error) and PBVS brings it "
            f"within {_goal_distance(rep)} of the tag, where 4 sub-pixel corners give precise "
            "poses; the real camera's noise, which made Est. 2 the noisiest in the paper,"
            " is not modelled. Among the others, "
            f"{min(others, key=maxes.get)} is best."
        )
    elif best == "image" and others:
        why += (
            " Here the image-based estimate is best instead, though its frames carry the "
            f"{rep.get('realism', {}).get('profile', 'realism')} profile's noise, blur, "
            "distortion and calibration error: PBVS brings the "
            f"camera within {_goal_distance(rep)} of the tag, and the rendered tag is sharp-edged "
            "ink on white "
            "paper (no lens blur, no pixel-area integration), so its corners stay sub-pixel "
            "accurate, while the control estimate accumulates the commanded-vs-achieved mismatch "
            f"over the whole servo. Among the others, "
            f"{min(others, key=maxes.get)} is best."
        )
    return Finding(
        finding="control-based estimate is the best with PBVS",
        paper="control ≤ 0.9 cm / 2°, best of all",
        twin=", ".join(f"{n} {v * 1e3:.1f} mm" for n, v in maxes.items()),
        threshold="control in the loop has the smallest max translational deviation",
        verdict=verdict(best == "control" if "control" in maxes else None),
        why=why,
    )


def _shares(g: dict) -> str:
    """Each source's variance share, e.g. "pixel_noise 62 %, homing 30 %"."""
    parts = []
    for name, st in g.items():
        share = st.get("variance_share_translation_m")
        if name.startswith("without ") and share is not None:
            parts.append(f"{name[len('without ') :]} {share * 100:.0f} %")
    return ", ".join(parts)


def repeatability(rep: dict) -> Finding | None:
    """The spread of the final pose at p1 over repetitions (the paper gives no number)."""
    acc = rep.get("accuracy", {})
    if not ("open loop" in acc and "PBVS (all)" in acc):
        return None
    spreads = {k: sample_std(acc[k]["translation_m"]) for k in ("open loop", "PBVS (all)")}
    counts = {k: len(acc[k]["translation_m"]) for k in spreads}
    decomposition = {k: _shares(g) for k, g in rep.get("spread", {}).items() if _shares(g)}
    if decomposition:
        why = (
            "what changes between repetitions on one robot is the per-run noise. Share of the "
            "variance that disappears with each source switched off: "
            + "; ".join(f"{k}: {v}" for k, v in decomposition.items())
            + ". Per-robot errors (geometry, calibration, drum radii, sensor bias) move every "
            "repetition alike: they set the mean, not the spread."
        )
    else:
        why = (
            "with the ideal profile the only thing that changes between repetitions is the "
            "tension-sensor noise, which the open-loop robot never reads and PBVS never sees, "
            "so runs repeat to micrometres; a realism profile (e.g. acrobot) adds pixel noise "
            "and homing."
        )
    nonzero = spreads["open loop"] > 1e-6 and spreads["PBVS (all)"] > 1e-6
    return Finding(
        finding="repeatability: spread of the final pose at p1 over repetitions",
        paper="10 open-loop and 30 PBVS runs with a visible spread (Fig. 8)",
        twin=f"std {spreads['open loop'] * 1e6:.1f} µm over {counts['open loop']} "
        f"open-loop runs, {spreads['PBVS (all)'] * 1e6:.1f} µm over "
        f"{counts['PBVS (all)']} PBVS runs",
        threshold="a spread above 1 µm with both controllers (the paper gives no number)",
        verdict=verdict(nonzero),
        why=why,
    )


def pbvs_goal(rep: dict) -> Finding | None:
    """Which PBVS goal the paper's accuracy points to: the nominal model's or a taught one."""
    sp = rep.get("spread", {}).get("PBVS control", {})
    ol = rep.get("spread", {}).get("open loop", {}).get("all")
    goals = {k[len("goal ") :]: v for k, v in sp.items() if k.startswith("goal ")}
    if ol is None or "all" not in sp or not goals:
        return None
    main_goal = rep.get("pbvs_goal", "file")
    rows = {main_goal: sp["all"], **goals}
    ratios = {
        g: (
            ol["mean_translation_m"] / v["mean_translation_m"],
            ol["mean_rotation_deg"] / v["mean_rotation_deg"],
        )
        for g, v in rows.items()
    }
    best = max(ratios, key=lambda g: min(ratios[g]))
    return Finding(
        finding="the PBVS goal the paper's procedure implies (nominal model vs taught at p1)",
        paper="PBVS 5× / 4× more accurate than open loop (translation / rotation)",
        twin="; ".join(
            f"goal {g}: {rt:.1f}× / {rr:.1f}× (PBVS control, {rows[g]['n']} runs)"
            for g, (rt, rr) in ratios.items()
        ),
        threshold=f"both ratios ≥ {MIN_ACCURACY_RATIO:g}× with one of the goals",
        verdict=verdict(min(ratios[best]) >= MIN_ACCURACY_RATIO),
        why=f"goal {best} gives the larger of the smaller ratios; the paper's 5× and 4× both "
        f"exceed {MIN_ACCURACY_RATIO:g}×, which a goal must reach in both to match them. A "
        "nominal goal carries the camera-mount and tag-placement errors into the final pose; a "
        "goal taught at the true p1 (teach-by-showing, the usual practice) cancels them.",
    )


def _rms_table(rep: dict) -> dict[str, dict[str, dict]]:
    """Each experiment's RMS deviations by estimator (open loop; PBVS with control in the loop)."""
    out = {}
    est = rep.get("open_loop", {}).get("estimators", {})
    if est and all("rms_translation_m" in v for v in est.values()):
        out["open loop"] = est
    pb = rep.get("pbvs", {}).get("control")
    if pb and "others_rms" in pb:
        out["PBVS (control in the loop)"] = {"control": pb, **pb["others_rms"]}
    return out


def fused_beats_each(rep: dict, name: str = "fused") -> Finding | None:
    """Beyond the paper (issue 11): the fused filter deviates less than every single estimator."""
    table = _rms_table(rep)
    if not table or not all(name in t and len(t) > 1 for t in table.values()):
        return None
    parts, losses = [], []
    for experiment, t in table.items():
        for part, loss in _comparisons(experiment, t, name):
            parts.append(part)
            if loss is not None:
                refs = {n: v[loss[3]] * loss[4] for n, v in t.items() if n not in (name, loss[0])}
                losses.append(_loss(experiment, loss[0], loss[1], loss[2], refs))
    repeated = [
        f"{exp}, {t[name]['n']} runs: " + "; ".join(p for p, _ in _comparisons(exp, t, name, False))
        for exp, t in rep.get("repetition_rms", {}).items()
        if name in t and len(t) > 1 and t[name]["n"] > 1
    ]
    ok = not losses
    return Finding(
        finding="fused (Est. 7, beyond the paper) beats every single estimator",
        paper="— (issue 11's goal: ≥ 2× better than the best single one)",
        twin="; ".join(parts),
        threshold="RMS translational and rotational deviation over the run below every other "
        "estimator's, in open loop and in PBVS with control in the loop",
        verdict=verdict(ok),
        why="cables give the motion precisely but carry the geometry error, the tag is noisy "
        "and biased by the camera's calibration: the filter weighs both by their modelled "
        "uncertainty (the geometry and calibration errors as considered states)."
        + "".join(losses)
        + (
            " Over every repetition (RMS over the runs, each with its own homing offset and "
            "noise; seed 1 above is one draw): "
            + ". ".join(repeated)
            + "."
            + _rotation_reference(rep, name)
            if repeated
            else ""
        ),
    )


def _rotation_reference(rep: dict, name: str) -> str:
    """Why the filter's rotation does not beat the control estimate's here, with the ratios."""
    rows = [
        f"{exp} {t['control']['rms_rotation_deg'] / t[name]['rms_rotation_deg']:.2f}×"
        for exp, t in rep.get("repetition_rms", {}).items()
        if name in t and "control" in t
    ]
    if not rows:
        return ""
    return (
        " Every measurement the filter fuses is relative to the start: the encoders are homed "
        "there and the tag is anchored at its first detection from the filter's own pose, so "
        "none tells it the homing offset's rotation, which the control estimate keeps as it is. "
        f"Over the runs its rotation is no better than control's ({', '.join(rows)}, control "
        "RMS / fused RMS). The filter's rotation is as uncertain as the geometry and "
        "calibration errors the robot's tolerances allow, and it weighs its sensors by that; "
        "the study has one robot, whose control and cable-based estimates happen to keep "
        "their rotation error small. Robot by robot, over 20 robots built to the same "
        "tolerances: "
        "campaigns/estimators_over_robots.toml (its report: "
        "docs/estimators_over_robots/report.md)."
    )


def _comparisons(experiment: str, t: dict, name: str, label: bool = True) -> list[tuple]:
    """(text, loss) per quantity: the filter against the best other estimator.

    ``loss`` is ``None`` where the filter wins, else (best, its value, unit, key, scale).
    """
    out = []
    for key, unit, scale in (("rms_translation_m", "mm", 1e3), ("rms_rotation_deg", "°", 1)):
        others = {n: v[key] for n, v in t.items() if n != name}
        best = min(others, key=others.get)
        ratio = others[best] / t[name][key]
        text = f"{experiment}: " if label else ""
        text += f"{t[name][key] * scale:.3g} {unit} vs {best} {others[best] * scale:.3g} {unit}"
        loss = None if ratio > 1.0 else (best, others[best] * scale, unit, key, scale)
        out.append((text + f" ({ratio:.2f}×)", loss))
    return out


def _loss(experiment: str, best: str, value: float, unit: str, refs: dict) -> str:
    """Why a single estimator beats the filter on one quantity, from the others' numbers."""
    cable = min((n for n in refs if n.startswith("model_")), key=refs.get, default=None)
    seen = [f"{n} {refs[n]:.3g} {unit}" for n in (cable, "image") if n in refs]
    text = f" Where it loses ({experiment}, {best} {value:.3g} {unit}), the single estimators "
    text += f"on its other sensors do worse ({', '.join(seen)})" if seen else "are missing"
    if best == "control":
        text += ": the control estimate keeps the error it starts with (homing) and adds only "
        text += "what the commanded motion misses, which a small motion keeps small"
    return text + "."


MIN_ACCURACY_RATIO = 3.0
"""PBVS must be at least this many times more accurate than open loop at p1 to agree."""


def pbvs_more_accurate(rep: dict, key: str, paper_ratio: float, unit: str) -> Finding | None:
    """PBVS ends nearer p1 than open loop, by about the paper's ratio (``key``: the error)."""
    ratios = rep.get("ratios")
    if not ratios:
        return None
    ok = ratios[key] >= MIN_ACCURACY_RATIO
    why = (
        "PBVS servoes the camera onto the tag, so at convergence only camera-mount, "
        "tag-placement and detection errors remain; open loop carries the full "
        "geometry error."
    )
    robot = rep.get("robot", {})
    if not ok and key == "rotation_deg" and robot:
        pb_rot = float(np.mean(rep["accuracy"]["PBVS (all)"]["rotation_deg"]))
        why += (
            f" Here this robot's camera mount is off by "
            f"{robot['camera_rotation_deg']:.2f}° and its tag by "
            f"{robot['tag_rotation_deg']:.2f}°: PBVS ends {pb_rot:.2f}° from p1 "
            "however well it converges, while its open-loop rotation error is small;"
            " the paper's larger ratio implies a camera and tag better calibrated "
            "relative to p1 than this draw."
        )
    return Finding(
        finding=f"PBVS more accurate than open loop at p1 ({unit})",
        paper=f"{paper_ratio:.0f}×",
        twin=f"{ratios[key]:.1f}×",
        threshold=f"mean open-loop / mean PBVS {unit} error ≥ {MIN_ACCURACY_RATIO:g}×",
        verdict=verdict(ok),
        why=why,
    )


def _goal_distance(rep: dict) -> str:
    """The PBVS goal's camera–tag distance, as words (the report's robot numbers)."""
    d = rep.get("robot", {}).get("goal_tag_distance_m", float("nan"))
    return "a short distance" if d != d else f"{d * 100:.0f} cm"
