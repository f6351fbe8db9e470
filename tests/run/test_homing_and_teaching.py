"""Tension sensors, homing repeatability and the PBVS goal taught by showing.

Statistical tolerances: a sample std of N Gaussian values has relative standard error
1/√(2(N − 1)) and a sample mean has standard error σ/√N; bounds below are ≥ 4 such errors
(false-failure odds < 1e-4 per check), the generators are seeded so each test is deterministic.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import A_BASE, B_PLATFORM

from cdpr_twin.controllers.pbvs import P1
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import pose_error, pose_from_vector, so3_log
from cdpr_twin.plugins import make_controller
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.robot.realism import (
    CameraRealism,
    HomingRealism,
    TensionRealism,
    draw_homing_offset,
    robot_rng,
    run_rng,
)
from cdpr_twin.run.homing_and_teaching import true_start_pose
from cdpr_twin.run.runner import prepare, run, start
from cdpr_twin.scenario.loading import MonitorConfig, ScenarioError, load_scenario
from cdpr_twin.sim.tension_sensors import TensionSensors
from cdpr_twin.types import Measurement, TagDetection

ROOT = Path(__file__).resolve().parents[2]
M = 8
ACCURACY = 0.24  # [N] the paper's sensor accuracy: a bound a, bias_std = a/√3 (GUM 4.3.7)
SPEC = TensionRealism(
    bias_std=ACCURACY / math.sqrt(3), gain_error_std=0.001, range_min=-25.0, range_max=75.0
)  # the paper's sensors (§IV-A)


def _sensors(realism=SPEC, noise_std=0.01, run_seed=1, robot_seed=19):
    return TensionSensors(
        M, noise_std, realism, np.random.default_rng(run_seed), robot_rng(robot_seed, "tension")
    )


def _scenario(file="paper_open_loop.toml", **realism_parts):
    s = load_scenario(ROOT / "scenarios" / file).with_realism("ideal")
    if file == "paper_open_loop.toml":
        s = s.with_overrides(camera=False, duration=0.2)
    return dataclasses.replace(s, realism=dataclasses.replace(s.realism, **realism_parts))


# ---------------------------------------------------------------------------- tension sensors
def test_ideal_sensors_read_truth_plus_the_run_seeds_noise_only():
    tau = np.linspace(3.0, 60.0, M)
    sensors = _sensors(TensionRealism(), noise_std=0.24, run_seed=7)
    rng = np.random.default_rng(7)  # the run seed's own stream, one normal(0, σ, m) per read
    for _ in range(3):
        reading, clipped = sensors.read(tau)
        np.testing.assert_array_equal(reading, tau + rng.normal(0.0, 0.24, M))
        assert clipped is None
    exact, _ = _sensors(TensionRealism(), noise_std=0.0).read(tau)
    assert exact is tau


def test_bias_and_gain_are_drawn_per_robot_with_the_specified_spread():
    n_robots = 2000  # 16 000 offsets and gain errors
    draws = [_sensors(robot_seed=k) for k in range(n_robots)]
    bias = np.concatenate([d.bias for d in draws])
    gain = np.concatenate([d.gain_error for d in draws])
    n = bias.size  # relative SE of a std: 1/√(2n) = 0.56 %; of a mean: σ/√n
    assert bias.std() == pytest.approx(SPEC.bias_std, rel=0.03)
    assert gain.std() == pytest.approx(SPEC.gain_error_std, rel=0.03)
    assert abs(bias.mean()) < 4 * SPEC.bias_std / math.sqrt(n)
    assert abs(gain.mean()) < 4 * SPEC.gain_error_std / math.sqrt(n)
    # a/√3 is the RMS of a uniform ±a: every offset stays within the datasheet's ±a, and they
    # fill it evenly (a uniform's quartiles are at ±a/2)
    assert np.all(np.abs(bias) <= ACCURACY + 1e-12)
    assert np.mean(np.abs(bias) <= ACCURACY / 2) == pytest.approx(0.5, abs=0.02)
    # one robot: the same sensors in every repetition (any run seed), others on another robot
    np.testing.assert_array_equal(_sensors(run_seed=2).bias, _sensors(run_seed=3).bias)
    np.testing.assert_array_equal(_sensors(run_seed=2).gain_error, _sensors().gain_error)
    assert not np.allclose(_sensors(robot_seed=1).bias, _sensors(robot_seed=2).bias)


def test_readings_carry_the_sensors_offset_gain_and_repeatability_noise():
    n = 2000  # readings per load, 8 sensors
    s = _sensors()
    loads = (0.0, 60.0)  # [N]: the offset alone, then offset + gain error
    means, stds = [], []
    for load in loads:
        r = np.array([s.read(np.full(M, load))[0] for _ in range(n)])
        means.append(r.mean(axis=0))
        stds.append(r.std(axis=0, ddof=1))
        noise = r - r.mean(axis=0)
        corr = np.corrcoef(noise.T)[np.triu_indices(M, 1)]  # sensors independent: SE 1/√n
        assert np.abs(corr).max() < 4.5 / math.sqrt(n)
        lag = np.sum(noise[1:] * noise[:-1], axis=0) / np.sum(noise**2, axis=0)
        assert np.abs(lag).max() < 4.5 / math.sqrt(n)  # readings independent in time
    se_mean = 0.01 / math.sqrt(n)  # 0.22 mN
    np.testing.assert_allclose(means[0], s.bias, atol=4.5 * se_mean)
    slope = (means[1] - means[0]) / loads[1]
    np.testing.assert_allclose(slope - 1.0, s.gain_error, atol=6.5 * se_mean / loads[1])
    np.testing.assert_allclose(np.concatenate(stds), 0.01, rtol=0.075)  # SE 1.6 %: 4.7 SE
    assert np.abs(s.bias).max() > 50 * se_mean  # the offsets are resolved, not noise


def test_readings_clip_at_the_range_and_say_so():
    realism = dataclasses.replace(SPEC, clip=True)
    clipping, free = _sensors(realism, run_seed=5), _sensors(SPEC, run_seed=5)
    sweep = np.linspace(-40.0, 90.0, 200)  # 200 reads × 8 sensors = 1 600 readings
    for load in sweep:
        tau = np.full(M, load)
        got, clipped = clipping.read(tau)
        raw, none = free.read(tau)  # the same offsets, gains and noise, never clipped
        assert none is None and clipped.dtype == bool and clipped.shape == (M,)
        low, high = raw <= realism.range_min, raw >= realism.range_max
        np.testing.assert_array_equal(clipped, low | high)
        np.testing.assert_array_equal(got[low], realism.range_min)
        np.testing.assert_array_equal(got[high], realism.range_max)
        np.testing.assert_array_equal(got[~clipped], raw[~clipped])
        # a load 1 N beyond the range always clips, 1 N inside never (|b| + |g τ| + noise < 1 N)
        if not realism.range_min - 1 < load < realism.range_max + 1:
            assert clipped.all()
        if realism.range_min + 1 < load < realism.range_max - 1:
            assert not clipped.any()


def test_clipped_readings_are_counted_per_cable_in_the_summary():
    s = _scenario(tension=TensionRealism(clip=True, range_max=1.0))  # every cable holds > 2 N
    # a tension beyond the sensor range is also a fault of the robot: here, go on regardless
    s = dataclasses.replace(s, monitor=MonitorConfig(on_fault="continue"))
    summary = run(s).summary
    reads = round(s.duration / s.model.control_period) + 1  # t = 0 and each tick
    assert summary["tension_clipped_readings"] == [reads] * M
    assert summary["faults"][0]["kind"] == "tension beyond the sensor range"
    assert "tension_clipped_readings" not in run(_scenario()).summary


# ---------------------------------------------------------------------------- homing
HOMING = HomingRealism(position_std=0.002, rotation_std=math.radians(0.3))


def test_homing_offsets_have_the_specified_spread_and_follow_the_run_seed():
    d = np.array([draw_homing_offset(HOMING, run_rng(seed, "homing")) for seed in range(2000)])
    np.testing.assert_allclose(d[:, :3].std(axis=0), HOMING.position_std, rtol=0.07)
    np.testing.assert_allclose(d[:, 3:].std(axis=0), HOMING.rotation_std, rtol=0.07)
    assert np.abs(d.mean(axis=0) / np.repeat([0.002, HOMING.rotation_std], 3)).max() < 0.1
    same = draw_homing_offset(HOMING, run_rng(3, "homing"))
    np.testing.assert_array_equal(same, d[3])
    np.testing.assert_array_equal(draw_homing_offset(HomingRealism(), run_rng(3, "homing")), 0)


def test_the_true_start_moves_by_the_offset_while_the_robot_believes_the_nominal_start():
    s, ideal = _scenario(homing=HOMING), _scenario()
    setup, ref = prepare(s), prepare(ideal)
    try:
        start(setup)
        start(ref)
        offset = setup.homing_offset
        np.testing.assert_array_equal(offset, draw_homing_offset(HOMING, run_rng(s.seed, "homing")))
        T, T0 = setup.physics.T_base_platform, s.start_pose
        np.testing.assert_allclose(T[:3, 3] - T0[:3, 3], offset[:3], atol=1e-9)
        np.testing.assert_allclose(so3_log(T[:3, :3] @ T0[:3, :3].T), offset[3:], atol=1e-9)
        # the winches hold other cable (mm) but the encoders read what they read at p0
        moved = np.abs(setup.physics.rest_lengths - ref.physics.rest_lengths).max()
        assert moved > 1e-3
        m, m0 = setup.sensors.read(None), ref.sensors.read(None)
        np.testing.assert_allclose(m.cable_lengths, m0.cable_lengths, atol=2e-6)  # E·S: µm
        # every estimator starts where the ideal run's does, at the nominal start
        for name, est in setup.estimate(m).items():
            want = ref.estimate(m0)[name].T_base_platform
            err = pose_error(est.T_base_platform, want)
            assert err["translation_m"] < 2e-6 and err["rotation_deg"] < 1e-4, name
        np.testing.assert_array_equal(setup.estimate(m)["control"].T_base_platform, T0)
    finally:
        setup.close()
        ref.close()


def test_homing_offset_in_the_summary_and_none_when_exact():
    s = _scenario(homing=HOMING)
    a, b = run(s).summary, run(s).summary
    assert a["homing_offset"] == b["homing_offset"]  # same seed, same offset
    other = run(s.with_overrides(seed=2)).summary["homing_offset"]
    assert other != a["homing_offset"]
    want = draw_homing_offset(HOMING, run_rng(s.seed, "homing"))
    np.testing.assert_allclose(a["homing_offset"]["position_m"], want[:3], rtol=1e-15)
    np.testing.assert_allclose(a["homing_offset"]["rotation_deg"], np.degrees(want[3:]))
    ideal = _scenario()
    setup = prepare(ideal)
    setup.close()
    assert setup.homing_offset is None and setup.true_start is ideal.start_pose
    assert "homing_offset" not in run(ideal).summary


def test_true_start_pose_composes_the_offset_in_the_base_frame():
    T0 = pose_from_vector([0.1, -0.2, 0.3, -12, -10, 0])
    T = true_start_pose(T0, np.array([0.001, 0.002, -0.003, 0.0, 0.0, math.pi / 2]))
    np.testing.assert_allclose(T[:3, 3], [0.101, -0.198, 0.297])
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(T[:3, :3], Rz @ T0[:3, :3], atol=1e-15)


# ---------------------------------------------------------------------------- PBVS goal
def _pbvs(**options):
    geometry = CdprGeometry(np.array(A_BASE), np.array(B_PLATFORM), 0.0045, 3.5e5, 3.5, np.zeros(3))
    goal = pose_from_vector([0.0, 0.0, 0.09, 0, 0, 0])
    return make_controller("pbvs", geometry, goal_T_cam_tag=goal, **options)


def _tag_measurement(T_cam_tag):
    tag = TagDetection(0, np.zeros((4, 2)), T_cam_tag, 50.0, 0.1)
    return Measurement(time=0.0, cable_lengths=np.ones(M), tensions=np.ones(M), tag=tag)


def test_teaching_sets_the_desired_feature_from_what_the_camera_measured():
    seen = pose_from_vector([0.001, -0.002, 0.091, 179, 1, 180])
    shown = []
    ctrl = _pbvs(goal="taught")
    ctrl.teach(lambda T: shown.append(T) or _tag_measurement(seen))
    np.testing.assert_array_equal(shown[0], pose_from_vector(P1))  # the paper's p1 by default
    np.testing.assert_array_equal(ctrl.goal_view, seen)
    np.testing.assert_array_equal(ctrl.goal_pose(None), pose_from_vector(P1))
    ctrl.reset(np.eye(4))
    np.testing.assert_array_equal(ctrl.goal_view, seen)  # learnt once, kept by reset
    nominal = _pbvs()
    nominal.teach(lambda T: pytest.fail("a nominal goal is not taught"))
    assert not nominal.taught


def test_goal_and_teach_pose_are_read_from_the_scenario_file(tmp_path):
    text = (ROOT / "scenarios" / "paper_pbvs.toml").read_text(encoding="utf-8")
    text = text.replace("../models", str(ROOT / "models"))
    good = text.replace(
        'type = "pbvs"', 'type = "pbvs"\ngoal = "taught"\nteach_pose = [0.28, -0.2, 0.1, 0, 0, 5]'
    )
    (tmp_path / "good.toml").write_text(good, encoding="utf-8")
    o = load_scenario(tmp_path / "good.toml").controller.options
    assert o.goal == "taught"
    np.testing.assert_allclose(o.teach_pose, pose_from_vector([0.28, -0.2, 0.1, 0, 0, 5]))
    (tmp_path / "bad.toml").write_text(good.replace('"taught"', '"shown"'), encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"controller\.goal"):
        load_scenario(tmp_path / "bad.toml")


def test_a_teach_pose_where_the_tag_is_not_seen_is_refused():
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml").with_realism("ideal")
    s = s.with_controller_options(
        goal="taught", teach_pose=pose_from_vector([-0.25, 0.25, 0.3, 0, 0, 0])
    )
    with pytest.raises(ScenarioError, match=r"controller\.teach_pose: the camera does not see"):
        prepare(s)


@pytest.mark.parametrize("latency_ticks", [0, 2])
def test_taught_and_nominal_goals_agree_on_an_ideal_robot(latency_ticks):
    """With a camera latency the robot waits at the pose until the frame exposed there arrives."""
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml").with_realism("ideal")
    camera = CameraRealism(latency_ticks=latency_ticks)
    s = dataclasses.replace(
        s, truth=DeviationSpec(seed=19), realism=dataclasses.replace(s.realism, camera=camera)
    ).with_controller_options(goal="taught")
    setup = prepare(s)
    setup.close()
    file_view = s.controller.options.goal_T_cam_tag
    # the nominal model's goal pose is p1, so the true view there is the file's view exactly …
    truth = pose_error(setup.shown_view, file_view)
    assert truth["translation_m"] < 1e-12 and truth["rotation_deg"] < 1e-9
    # … and the taught view equals it to the ideal camera's detection accuracy at 9 cm
    # (measured 4.5 µm / 1e-5°; bounds: 0.05 mm, 0.01°)
    taught = pose_error(setup.controller.goal_view, file_view)
    assert taught["translation_m"] < 5e-5 and taught["rotation_deg"] < 0.01
    np.testing.assert_array_equal(setup.goal_pose, pose_from_vector(P1))


@pytest.mark.slow
def test_a_taught_goal_ends_pbvs_nearer_the_true_p1_on_the_deviated_robot():
    """Measured (robot seed 19, run seed 1): nominal 3.05 mm / 1.19°, taught 0.30 mm / 0.002°."""
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml").with_realism("ideal")
    nominal = run(s).summary
    taught = run(s.with_controller_options(goal="taught")).summary
    assert nominal["status"] == taught["status"] == "converged"
    np.testing.assert_allclose(taught["goal_pose"], P1, atol=1e-12)
    np.testing.assert_allclose(nominal["goal_pose"], P1, atol=1e-12)  # p1 as the model says
    end = {k: r["final_error_vs_goal"] for k, r in (("nominal", nominal), ("taught", taught))}
    assert end["taught"]["translation_m"] < 0.2 * end["nominal"]["translation_m"]
    assert end["taught"]["rotation_deg"] < 0.1 * end["nominal"]["rotation_deg"]
    assert end["taught"]["translation_m"] < 1e-3  # within reach of the 0.3 mm convergence
    assert end["nominal"]["translation_m"] > 2e-3  # the camera/tag mounting errors, carried
    assert taught["pbvs"]["goal"] == "taught" and "goal" not in nominal["pbvs"]


@pytest.mark.slow
def test_a_focal_length_error_shifts_a_nominal_goal_along_the_optical_axis_not_a_taught_one():
    """PBVS with a miscalibrated focal length (ideal camera otherwise, no geometry error).

    The detector scales a tag's depth by the focal error: ẑ = z·(1 + δ̄), δ̄ the mean relative
    error of fx and fy, so the servo stops where ẑ equals the goal's 9 cm, δ̄·z/(1 + δ̄) nearer
    the tag along the optical axis (first order; measured 2.86 mm, predicted 2.74 mm). A goal
    taught at p1 carries the same error and cancels it: the robot stops at p1 to what the
    convergence thresholds (0.3 mm, 0.1° of the measured view) leave free (0.40 mm / 0.17°;
    the nominal run ends with the same sideways 0.4 mm / 0.18°, its approach's).
    """
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml").with_realism("ideal")
    s = dataclasses.replace(  # 1 cm from p1: a short run
        s,
        truth=DeviationSpec(seed=19),
        realism=dataclasses.replace(s.realism, camera=CameraRealism(focal_error_std=0.03)),
        start_pose=pose_from_vector([0.29, -0.19, 0.085, 1, -1, 2]),
        duration=25.0,  # converged after 14 s
    )
    setup = prepare(s)
    K, K_true = setup.sensors.camera.calibrated, setup.sensors.camera.true_intrinsics
    setup.close()
    delta = (K.fx / K_true.fx + K.fy / K_true.fy) / 2 - 1
    assert abs(delta) > 0.02  # the drawn error (robot seed 19: fx −1.1 %, fy +7.4 %)
    ends = {g: run(s.with_controller_options(goal=g)).summary for g in ("nominal", "taught")}
    assert all(e["status"] == "converged" for e in ends.values())
    shift = np.subtract(ends["nominal"]["final_pose"][:3], P1[:3])
    z_goal = s.controller.options.goal_T_cam_tag[2, 3]
    predicted = delta * z_goal / (1 + delta)  # nearer the tag: down, the camera looks down
    assert shift[2] == pytest.approx(-predicted, rel=0.1)
    assert np.hypot(shift[0], shift[1]) < 0.25 * predicted  # along the axis (measured 0.15)
    taught = ends["taught"]["final_error_vs_goal"]
    assert taught["translation_m"] < 0.25 * np.linalg.norm(shift) and taught["rotation_deg"] < 0.3
