"""The paper's findings, checked against the twin's numbers: one small rule per finding.

Each rule reads the report numbers (:func:`cdpr_twin.study.analyse`) and returns a
:class:`Finding`, or ``None`` without the numbers it needs; :func:`evaluate` applies them all.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from functools import partial

from cdpr_twin.estimators import PAPER_ESTIMATORS
from cdpr_twin.study.findings_pbvs import (
    MIN_ACCURACY_RATIO,
    control_best_with_pbvs,
    fused_beats_each,
    pbvs_goal,
    pbvs_more_accurate,
    repeatability,
)
from cdpr_twin.study.verdicts import (
    AGREES,
    DISAGREES,
    NOT_APPLICABLE,
    Finding,
    Rule,
    length,
    verdict,
)

__all__ = [
    "AGREES",
    "DISAGREES",
    "FINDINGS",
    "MIN_ACCURACY_RATIO",
    "NOT_APPLICABLE",
    "Finding",
    "Rule",
    "evaluate",
    "verdict",
]


def open_loop_miss(rep: dict) -> Finding | None:
    """The robot misses p1 by about a centimetre in open loop."""
    miss = rep.get("open_loop", {}).get("miss_at_p1")
    if not miss:
        return None
    m = miss["translation_m"]
    return Finding(
        finding="open-loop error at p1 ≈ 1 cm (goal 0.5–2 cm)",
        paper="≈ 1 cm",
        twin=f"{m * 100:.2f} cm / {miss['rotation_deg']:.2f}°",
        threshold="0.5 cm ≤ translational error at p1 ≤ 2 cm",
        verdict=verdict(0.005 <= m <= 0.02),
        why="Â uses the nominal geometry; the robot's exit and anchor points differ "
        + _geometry_error(rep.get("robot", {}))
        + ", so integrating l̇ = Â ᵇv_p lands elsewhere.",
    )


def estimates_follow_plan(rep: dict) -> Finding | None:
    """The control- and model-based estimates sit on the plan, not on the robot."""
    ol = rep.get("open_loop", {})
    fp, miss = ol.get("follow_plan"), ol.get("miss_at_p1")
    names = [n for n in fp or {} if n != "image" and n in PAPER_ESTIMATORS]
    if not (fp and miss and names):
        return None
    worst = max(fp[n]["vs_plan_m"] for n in names)
    return Finding(
        finding="control and model estimates follow the plan, not the robot",
        paper="estimates ≈ p1 while the MP is ≈ 1 cm away",
        twin=f"at t = {miss['time_s']:g} s: ≤ {worst * 1e3:.2f} mm from the plan, robot "
        f"{miss['translation_m'] * 1e3:.1f} mm from it",
        threshold="every non-image estimate < ¼ of the robot's miss from the plan at p1",
        verdict=verdict(worst < 0.25 * miss["translation_m"]),
        why="the control estimate integrates the commanded (planned) twist; the "
        "model-based ones invert the same nominal model the plan was made "
        "with, from encoder lengths that follow the plan exactly"
        + _off_plan(fp, names, miss["translation_m"]),
    )


def _off_plan(fp: dict, names: list[str], miss: float) -> str:
    """Which estimates leave the plan by more than the criterion, and by how much."""
    off = {n: fp[n]["vs_plan_m"] for n in names if fp[n]["vs_plan_m"] >= 0.25 * miss}
    if not off:
        return "."
    parts = ", ".join(f"{n} {length(v)}" for n, v in off.items())
    return (
        f"; here the tensions' corrections move these off the plan ({parts} at p1): "
        "the cable effects they model are as large as the robot's miss."
    )


def _image_noisiest_in_pbvs(rep: dict) -> bool | None:
    """In the control-in-loop PBVS run, is the passive image estimate the roughest?"""
    pb = rep.get("pbvs", {}).get("control")
    if pb is None or "image" not in pb["others_roughness_m"]:
        return None
    others = [v for n, v in pb["others_roughness_m"].items() if n != "image"]
    return not others or pb["others_roughness_m"]["image"] > max(others)


def image_noisiest(rep: dict) -> Finding | None:
    """The image-based estimate is the noisiest (open loop, and PBVS when there)."""
    est = rep.get("open_loop", {}).get("estimators", {})
    others = [v["roughness_m"] for n, v in est.items() if n != "image"]
    if "image" not in est or not others:
        return None
    r_img, r_oth = est["image"]["roughness_m"], max(others)
    pb_ok = _image_noisiest_in_pbvs(rep)
    why = (
        "it rests on 4 tag corners"
        + _tag_view(rep)
        + (
            ": their pixel errors give tilt errors that the camera–tag lever arm turns into "
            "platform position errors."
        )
    )
    if pb_ok is False:
        pb = rep["pbvs"]["control"]
        rough = pb["others_roughness_m"]
        worst = max(rough, key=rough.get)
        jump, at = pb.get("others_max_jump", {}).get(worst, (float("nan"), float("nan")))
        late = {  # an undefined roughness (NaN; null in report.json) gets no sentence
            n: v
            for n, v in pb.get("others_roughness_after_start_m", {}).items()
            if v is not None and math.isfinite(v)
        }
        why += (
            f" With PBVS (control in the loop) {worst} is rougher ({rough[worst] * 1e3:.2f} mm "
            f"vs image {rough['image'] * 1e3:.2f} mm) because of one jump of {jump * 1e3:.1f} mm "
            f"at t = {at:.2f} s, when the servo's start swings the cable tensions and the six "
            "most-tensioned cables of Algorithm 1 form an ill-conditioned set"
        )
        if worst in late and "image" in late:
            why += (
                f"; after the first 0.5 s it is {late[worst] * 1e3:.3f} mm against image's "
                f"{late['image'] * 1e3:.3f} mm"
            )
        why += "."
    return Finding(
        finding="image-based estimate is the noisiest",
        paper="noisiest with both controllers",
        twin=f"tick-to-tick RMS {r_img * 1e3:.3f} mm vs ≤ {r_oth * 1e3:.3f} mm for "
        "the others (open loop)",
        threshold="largest tick-to-tick RMS change of all estimates, open loop and "
        "(when run) PBVS with control in the loop",
        verdict=verdict(r_img > r_oth and (pb_ok is None or pb_ok)),
        why=why,
    )


def image_noise_grows_with_distance(rep: dict) -> Finding | None:
    """The image-based estimate is noisier far from the tag than near it."""
    imd = rep.get("open_loop", {}).get("image_distance")
    if not imd:
        return None
    return Finding(
        finding="image-based gets noisier farther from the tag",
        paper="good near the tag (t = 8–12 s), highly noisy far",
        twin=f"tick-to-tick RMS {imd['near_noise_m'] * 1e3:.3f} mm at "
        f"{imd['near_distance_m']:.2f} m vs {imd['far_noise_m'] * 1e3:.3f} mm "
        f"at {imd['far_distance_m']:.2f} m (Spearman {imd['spearman']:.2f}); "
        f"mean deviation {imd['near_mean_deviation_m'] * 1e3:.2f} mm near vs "
        f"{imd['far_mean_deviation_m'] * 1e3:.2f} mm far",
        threshold="noise in the farthest third > in the nearest third, and Spearman > 0",
        verdict=verdict(imd["far_noise_m"] > imd["near_noise_m"] and imd["spearman"] > 0),
        why="the tag shrinks in the image and its corners carry less pose "
        "information (tilt observability falls as (s/2Z)²). The mean "
        "deviation is a different story: it is a bias from the camera-mount "
        "error and the reference taken at p0, and grows with the motion "
        "since p0, which brings the camera near the tag.",
    )


def model_variants_agree(rep: dict) -> Finding | None:
    """The four model-based variants give nearly the same pose."""
    mv = rep.get("open_loop", {}).get("model_variants")
    if not mv:
        return None
    return Finding(
        finding=f"the {_count(mv.get('n_variants', 4))} model-based variants are nearly identical",
        paper="almost the same output (on ACROBOT)",
        twin="max difference between variants "
        f"{mv['max_pairwise_difference_m'] * 1e3:.2f} mm vs their deviation from truth "
        f"up to {mv['max_deviation_m'] * 1e3:.1f} mm",
        threshold="largest difference between variants < 10 % of their largest deviation",
        verdict=verdict(mv["max_pairwise_difference_m"] < 0.1 * mv["max_deviation_m"]),
        why=f"stretch τ·l/(E·S) is at most {length(mv['max_stretch_m'])} and "
        f"the pulley wrap (l_pulley − l_straight, "
        f"{mv['wrap_min_m'] * 1e3:.2f}–{mv['wrap_max_m'] * 1e3:.2f} mm) changes "
        f"by at most {mv['wrap_change_max_m'] * 1e3:.2f} mm along the run"
        + _sag_words(mv, rep.get("robot", {}))
        + _against(rep.get("robot", {}), mv),
    )


def _count(n: int) -> str:
    return {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}.get(n, str(n))


def _sag_words(mv: dict, robot: dict) -> str:
    sag = mv.get("max_sag_m", float("nan"))
    if sag != sag:
        return ""
    if robot.get("sag_simulated"):
        return f"; the cables, heavy in the physics here, sag by up to {length(sag)}"
    return f"; the cables, massless here, would sag ≤ {sag * 1e3:.1f} mm"


def _against(robot: dict, mv: dict) -> str:
    """What the cable effects compare with: the geometry errors, if the report has them."""
    if "exit_point_error_max_m" not in robot:
        return ", against the robot's geometry errors."
    effects = max(mv["max_stretch_m"], mv["wrap_change_max_m"], mv.get("max_sag_m", 0.0) or 0.0)
    geometry = max(robot["exit_point_error_max_m"], robot["anchor_point_error_max_m"])
    if effects < 0.1 * geometry:
        return f", against geometry errors up to {length(geometry)}."
    return (
        f", as large as the robot's geometry errors (up to {length(geometry)}): the variants "
        "that model them and those that do not land apart."
    )


def _geometry_error(robot: dict) -> str:
    if "exit_point_error_max_m" not in robot:
        return "from it (calibration errors)"
    top = max(robot["exit_point_error_max_m"], robot["anchor_point_error_max_m"])
    return f"by up to {length(top)}"


def _tag_view(rep: dict) -> str:
    """The tag's size and the open-loop run's camera–tag distances, as words ("" if unknown)."""
    robot, imd = rep.get("robot", {}), rep.get("open_loop", {}).get("image_distance")
    size = robot.get("tag_size_m", float("nan"))
    if imd is None or size != size:
        return ""
    return (
        f"; a {length(size)} tag seen from "
        f"{imd['near_distance_m']:.2f}–{imd['far_distance_m']:.2f} m"
    )


FINDINGS: tuple[Rule, ...] = (
    open_loop_miss,
    estimates_follow_plan,
    image_noisiest,
    image_noise_grows_with_distance,
    model_variants_agree,
    control_best_with_pbvs,
    repeatability,
    pbvs_goal,
    partial(pbvs_more_accurate, key="translation_m", paper_ratio=5.0, unit="translation"),
    partial(pbvs_more_accurate, key="rotation_deg", paper_ratio=4.0, unit="rotation"),
    fused_beats_each,
)  # every finding's rule, in report order


def evaluate(rep: dict, rules: tuple[Rule, ...] = FINDINGS) -> list[dict]:
    """Each finding whose numbers are in ``rep``, as a dict (``report.json``'s ``findings``)."""
    return [asdict(f) for rule in rules if (f := rule(rep)) is not None]
