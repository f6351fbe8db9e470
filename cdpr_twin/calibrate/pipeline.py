"""One calibration of a scenario's robot: excite, record, solve, check against the truth.

The solver sees the recording's :class:`~cdpr_twin.calibrate.problem.Observations`, the
nominal model and the builder's tolerances (the scenario's ``[truth]`` magnitudes and the
realism profile's drum radius tolerance — magnitudes, not the drawn errors). The twin's truth
enters only :func:`truth_check`, after the solve, for the report.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np

from cdpr_twin.calibrate.acquire import Recording, record
from cdpr_twin.calibrate.excitation import excitation_poses
from cdpr_twin.calibrate.problem import Priors, Problem
from cdpr_twin.calibrate.solver import Calibration, CalibrationError, solve_weighted
from cdpr_twin.calibrate.variance import NoiseModel, Weighting
from cdpr_twin.math.se3 import pose_distance, so3_log
from cdpr_twin.scenario.loading import Scenario, ScenarioError

NOISE = NoiseModel(tag_std_per_m=6e-3, tag_rotation_std=math.radians(1.0))
"""The noise the solver starts from, upper bounds for the twin's ``acrobot`` profile: the tag's
position error grows to ≈ 3 mm along the optical axis at 0.45 m and its rotation errors reach
1–3° (a 4 cm tag, the intrinsics' calibration error, before that error is estimated; seen on
seed 19), the encoders' count is 31 µm. The force balance's noise comes from the recording
(:func:`noise_of`). The solve then re-estimates each group's noise from its own residuals
(:func:`~cdpr_twin.calibrate.solver.solve_weighted`; robots 1–20: the tag's lateral noise
0.06–0.09× this, its depth 0.20–0.27×, its rotation 0.32–0.47×, the cables 0.54–0.62×)."""

FORCE_FLOOR = 0.01
"""What the force balance misses beside the readings' noise [N per axis]: the cables' own
weight (2.4 g/m on ACROBOT, ≈ 0.1 N over the eight, which changes a little with the pose) and
the directions' errors; at robot 8's true geometry and poses, with each sensor's offset and
gain fitted, the balance's residual is 0.006–0.010 N per axis (acrobot profile, 240 poses)."""


@dataclass(frozen=True, eq=False)
class Outcome:
    """A calibration and what it came from.

    Attributes:
        calibration: the solution.
        recording: the readings (and the truth, kept apart).
        priors: the tolerances the solver used.
        excitation_s: time to choose the poses [s].
        dropped: recorded poses left out: no equation beyond their own six unknowns
            (:attr:`~cdpr_twin.calibrate.problem.Observations.redundancy`).
        noise: the measurement noise the solver weighed the residuals with (after the
            variance components).
        weighting: how the residuals came to be weighted (variance components,
            :func:`~cdpr_twin.calibrate.solver.solve_weighted`); ``None``: as ``noise`` says.
    """

    calibration: Calibration
    recording: Recording
    priors: Priors
    excitation_s: float
    dropped: int = 0
    noise: NoiseModel = NOISE
    weighting: Weighting | None = None


MOMENT_ARM = 0.1
"""The moment balance's noise over the force balance's [m]: the anchors' lever arm on ACROBOT
(at robot 8's truth, fitted as for :data:`FORCE_FLOOR`: 0.0011–0.0014 N·m per axis)."""

HOME_FLOOR = 1e-5
"""Where homing is exact, the home readings' pose is still the settled robot's [m, rad]."""


def noise_of(rec: Recording, frames: int) -> NoiseModel:
    """:data:`NOISE` with the force balance's noise.

    Each of the m readings' noise (averaged over ``frames``) counted whole on each axis, and
    :data:`FORCE_FLOOR`.
    """
    reading = rec.tension_sensors[2] * math.sqrt(rec.obs.encoder.shape[1] / frames)
    force = math.hypot(FORCE_FLOOR, reading)
    return replace(NOISE, force_std=force, moment_std=force * MOMENT_ARM)


def priors_of(s: Scenario, focal_px: float, tension: tuple[float, float, float]) -> Priors:
    """The builder's tolerances of a scenario's robot (its ``[truth]`` magnitudes).

    And the camera calibration's (the realism profile's; ``focal_px`` turns the relative focal
    error into pixels), and the tension sensors' (``tension``: their datasheet's offset std
    [N] and relative gain error std, :attr:`Recording.tension_sensors`).
    """
    t, tiny = s.truth, 1e-7  # a zero tolerance: the block is known (kept at nominal)
    c = s.realism.camera
    lens = np.broadcast_to(np.asarray(c.distortion_error_std, dtype=float), (4,))
    intrinsics = [focal_px * c.focal_error_std] * 2 + [c.center_error_std_px] * 2 + list(lens)
    return Priors(
        exit=max(t.exit_point_std, tiny),
        anchor=max(t.anchor_point_std, tiny),
        scale=max(s.realism.winch.drum_radius_error_std, tiny),
        camera_position=max(t.camera_position_std, tiny),
        camera_rotation=max(t.camera_rotation_std, tiny),
        tag_position=max(t.tag_position_std, tiny),
        tag_rotation=max(t.tag_rotation_std, tiny),
        tension_bias=max(tension[0], tiny),
        tension_gain=max(tension[1], tiny),
        home_position=max(s.realism.homing.position_std, HOME_FLOOR),
        home_rotation=max(s.realism.homing.rotation_std, HOME_FLOOR),
        intrinsics=tuple(max(float(v), tiny) for v in intrinsics),
    )


def calibrate(
    s: Scenario,
    n_poses: int = 240,
    frames: int = 4,
    workers: int = 1,
    progress: Callable[[str, int, int], None] | None = None,
) -> Outcome:
    """Excite, record and calibrate the robot of scenario ``s``.

    ``workers`` processes record the tour's segments side by side (the result does not depend
    on their number). ``progress`` is told each stage: ``("recording", done, segments)`` as
    segments end, then ``("solving", 0, 0)``.

    Raises:
        ScenarioError: the scenario's robot cannot be built or has no camera.
        CalibrationError: no excitation poses, the tag never seen, or no convergence.
    """
    from cdpr_twin.sim import build_robot

    started = time.perf_counter()
    nominal = build_robot(s.model.file, nominal_path=s.model.nominal).nominal
    if nominal.intrinsics is None or nominal.T_base_tag is None:
        raise ScenarioError(
            f"{s.source}: model.file: {s.model.file} has no camera or no tag; calibration "
            "needs both (add [camera] and [tag] to the robot description)"
        )
    try:
        poses = excitation_poses(
            nominal.geometry,
            nominal.T_base_tag,
            nominal.intrinsics,
            nominal.tag_size,
            n_poses,
            s.start_pose,
        )
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    chosen = time.perf_counter() - started
    tell = progress or (lambda stage, done, total: None)
    tell("recording", 0, 1)
    rec = record(s, poses, frames, workers, lambda done, total: tell("recording", done, total))
    if not rec.obs.seen.any():
        raise CalibrationError(
            "the tag was never detected at the excitation poses; check the camera and tag in "
            "the robot description (cdpr-twin demo shows what the camera sees)"
        )
    keep = rec.obs.redundancy > 0
    rec = rec.subset(keep)
    priors = priors_of(s, rec.detector.focal_px, rec.tension_sensors)
    noise = noise_of(rec, frames)
    problem = Problem(nominal.geometry, nominal.T_base_tag, rec.obs, priors, noise, rec.detector)
    tell("solving", 0, 0)
    cal, weighting = solve_weighted(problem)
    return Outcome(
        cal, rec, priors, chosen, int(np.count_nonzero(~keep)), weighting.noise, weighting
    )


def _fit(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motion that best fits P onto Q (Kabsch): R (3, 3), and P moved by it (m, 3)."""
    pc, qc = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - pc).T @ (Q - qc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, (P - pc) @ R.T + qc


def _mm(x: np.ndarray) -> list[float]:
    return np.round(np.asarray(x) * 1e3, 3).tolist()


def truth_check(outcome: Outcome, nominal_geometry, nominal_T_base_tag) -> dict:
    """The calibrated and nominal models' errors against the twin's truth (report only)."""
    cal, truth = outcome.calibration.model, outcome.recording.truth
    g = truth.geometry
    out: dict = {}
    for name, a, b, T_cam, T_tag in (
        (
            "nominal",
            nominal_geometry.a_base,
            nominal_geometry.b_platform,
            nominal_geometry.T_platform_cam,
            nominal_T_base_tag,
        ),
        ("calibrated", cal.a_base, cal.b_platform, cal.T_platform_cam, cal.T_base_tag),
    ):
        e_a = np.linalg.norm(a - g.a_base, axis=1)
        R, fitted = _fit(a, g.a_base)
        e_shape = np.linalg.norm(fitted - g.a_base, axis=1)
        e_b = np.linalg.norm(b - g.b_platform, axis=1)
        cam, tag = pose_distance(T_cam, g.T_platform_cam), pose_distance(T_tag, truth.T_base_tag)
        out[name] = {
            "exit_error_mm": _mm(e_a),
            "exit_error_median_mm": float(np.median(e_a) * 1e3),
            "exit_shape_error_median_mm": float(np.median(e_shape) * 1e3),
            # the frame error that shape leaves out: the fit's rotation (x, y: tilt; z: about
            # the vertical) and the exit points' centroid offset
            "exit_frame_rotation_deg": np.round(np.degrees(so3_log(R.T)), 4).tolist(),
            "exit_frame_shift_mm": _mm((a - g.a_base).mean(axis=0)),
            "anchor_error_median_mm": float(np.median(e_b) * 1e3),
            "camera_error_mm_deg": [cam[0] * 1e3, math.degrees(cam[1])],
            "tag_error_mm_deg": [tag[0] * 1e3, math.degrees(tag[1])],
        }
    dt, dr = pose_distance(cal.T_base_platform, truth.T_base_platform)
    out["calibrated"]["pose_error_median_mm_deg"] = [
        float(np.median(dt) * 1e3),
        float(np.degrees(np.median(dr))),
    ]
    out["calibrated"]["drum_scale_error"] = np.round(cal.scale - truth.drum_scale, 6).tolist()
    if any(n.startswith("tension_bias") for n in outcome.calibration.names):  # force balance
        out["nominal"]["tension_bias_n"] = np.round(truth.tension_bias, 4).tolist()
        out["calibrated"]["tension_bias_error_n"] = np.round(
            cal.tension_bias - truth.tension_bias, 4
        ).tolist()
    if "intrinsics" in outcome.calibration.names[-1]:  # the detector's intrinsics estimated
        est = outcome.calibration.estimate[-8:]
        out["nominal"]["intrinsics_error"] = np.round(truth.intrinsics_error, 6).tolist()
        out["calibrated"]["intrinsics_error"] = np.round(est - truth.intrinsics_error, 6).tolist()
    out["note"] = (
        "exit_shape: after the rigid motion that best fits the estimate onto the truth (the "
        "base frame is a gauge the data cannot see: only the priors place it)"
    )
    return out


def weighting_report(outcome: Outcome) -> dict:
    """The noise model the solution was weighted with and how it came about (JSON-ready)."""
    w = outcome.weighting
    components = None
    if w is not None:
        components = {
            "rounds": list(w.rounds),
            "settled": w.settled,
            "note": w.note,
            "tag_views_left_out": list(w.left_out),
        }
    return {"noise_model": asdict(outcome.noise), "variance_components": components}
