"""The Gymnasium environment: Gymnasium's checker passes, actions move the platform as they
say, seeds draw the robot and the noise, and a proportional pose controller written here
(reading only the observation) brings the platform within 5 mm of a goal pose."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from cdpr_twin.gym import ENV_IDS, CdprEnv, ReachPose
from cdpr_twin.math.se3 import pose_distance, so3_exp, so3_log

OBSERVATION_KEYS = {"cable_lengths", "tensions", "tag_detected", "tag_pose", "pose_estimate"}


UNBOUNDED = ("maximum value is infinity", "minimum value is -infinity")
"""Gymnasium's heuristic warning on an infinite bound. Tensions (an overloaded cable's, before
the monitor stops the episode), encoder lengths (a large robot's) and an estimate's position
(a lost estimator's) have no bound in physics: a finite one would be a false promise."""


def _checked(env) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    messages = [str(w.message) for w in caught if "WARN" in str(w.message)]
    return [
        m for m in messages if not ("observation space" in m and any(u in m for u in UNBOUNDED))
    ]


def test_check_env_passes_for_the_registered_reach_environment():
    env = gymnasium.make("cdpr_twin/Reach-v0")  # its spec lets check_env try render modes
    try:
        assert _checked(env.unwrapped) == []
    finally:
        env.close()
    assert set(ENV_IDS) <= set(gymnasium.registry)


def test_check_env_passes_with_the_camera_image_and_cable_rates():
    env = gymnasium.make("cdpr_twin/ServoToTag-v0", action="cable_rates", image=True).unwrapped
    try:
        assert _checked(env) == []
        obs, _ = env.reset(seed=0)
        assert set(obs) == OBSERVATION_KEYS | {"image"}
        assert obs["image"].shape == (480, 640, 3) and obs["image"].dtype == np.uint8
        assert obs["tag_detected"] == 1  # the tag is in view at p0
        assert env.action_space.shape == (8,)
    finally:
        env.close()


def test_seeds_draw_the_robot_and_the_noise():
    env = CdprEnv()
    try:
        a, info_a = env.reset(seed=5)
        geometry_a = env._setup.physics.geometry.a_base.copy()
        nominal_a = env.nominal_geometry.a_base.copy()
        b, info_b = env.reset(seed=5)
        assert info_a["robot_seed"] == info_b["robot_seed"]
        for key in OBSERVATION_KEYS:
            np.testing.assert_array_equal(a[key], b[key])
        c, info_c = env.reset(seed=6)
        assert info_c["robot_seed"] != info_a["robot_seed"]
        assert np.abs(env._setup.physics.geometry.a_base - geometry_a).max() > 1e-3  # exit points
        np.testing.assert_array_equal(env.nominal_geometry.a_base, nominal_a)  # what it believes
        assert not np.array_equal(a["tensions"], c["tensions"])
    finally:
        env.close()
    fixed = CdprEnv(random_robot=False)
    try:
        _, info = fixed.reset(seed=5)
        assert info["robot_seed"] == 19  # the scenario's robot
    finally:
        fixed.close()


def test_actions_move_the_platform_as_they_say():
    env = CdprEnv(realism="ideal", truth_scale=0.0)
    try:
        _, info = env.reset(seed=0)
        start = info["T_base_platform"][:3, 3]
        for _ in range(10):  # 0.4 s at 0.05 m/s along x of the base frame
            _, _, _, _, info = env.step(np.array([0.5, 0, 0, 0, 0, 0], dtype=np.float32))
        moved = info["T_base_platform"][:3, 3] - start
        assert moved[0] == pytest.approx(0.02, rel=0.1) and np.abs(moved[1:]).max() < 1e-3
    finally:
        env.close()
    env = CdprEnv(action="cable_rates", realism="ideal", truth_scale=0.0)
    try:
        _, info = env.reset(seed=0)
        z0 = info["T_base_platform"][2, 3]
        for _ in range(10):  # every cable paid out 0.4 s at 0.02 m/s: the platform sinks
            _, _, _, _, info = env.step(np.full(8, 0.2, dtype=np.float32))
        assert info["T_base_platform"][2, 3] < z0 - 0.005
    finally:
        env.close()


def test_a_proportional_pose_controller_reaches_the_goal_within_5_mm():
    """The controller reads the observation only (``pose_estimate``, from the encoders and
    tension sensors); the truth in ``info`` is read to check it. Nominal robot, ideal sensors:
    with the scenario's calibration errors the estimate (hence the goal reached) is off by
    their effect, as in the paper's open loop."""
    task = ReachPose(goal=(0.25, -0.15, 0.12, 3.0, -2.0, 5.0))
    env = CdprEnv(task=task, realism="ideal", truth_scale=0.0)
    gain, slew = 1.5, 0.05  # 1/s; action change per tick (a full-speed step slackens cables)
    try:
        obs, info = env.reset(seed=3)
        assert set(obs) == OBSERVATION_KEYS
        start_error = info["translation_error"]
        goal = task.goal_pose
        action = np.zeros(6)
        for _ in range(500):
            p = obs["pose_estimate"]
            v = gain * (goal[:3, 3] - p[:3])
            w = gain * so3_log(goal[:3, :3] @ so3_exp(p[3:]).T)
            wanted = np.clip(np.concatenate([v, w]) / env.action_scale, -1, 1)
            action = action + np.clip(wanted - action, -slew, slew)
            obs, reward, terminated, truncated, info = env.step(action.astype(np.float32))
            if terminated or truncated:
                break
        assert terminated and info["is_success"] and not truncated
        error_t, error_r = pose_distance(info["T_base_platform"], goal)
        assert start_error > 0.2 and error_t < 0.005, error_t
        assert np.degrees(error_r) < 0.2
        assert reward == pytest.approx(-(error_t + task.rotation_weight * error_r))
    finally:
        env.close()


def test_the_servo_task_is_achieved_at_p1_on_the_nominal_robot():
    # the scene places the tag so that the nominal camera sees the paper's goal view ᶜp_o1 at p1
    from cdpr_twin.gym import ServoToTag, Truth
    from cdpr_twin.gym.tasks import P1
    from cdpr_twin.math.se3 import pose_from_vector
    from cdpr_twin.sim import Twin

    with Twin(robot="acrobot", camera=False, tension_noise_std=0.0) as twin:
        twin.reset(pose_from_vector(P1))
        at_p1 = Truth(twin.T_base_platform.copy(), twin.T_cam_tag.copy())
        twin.reset(pose_from_vector([0.27, -0.18, 0.09, 0, 0, 0]))
        nearby = Truth(twin.T_base_platform.copy(), twin.T_cam_tag.copy())
    servo, reach = ServoToTag(), ReachPose()
    score = servo.score(at_p1)
    assert score.success and score.translation_error < 1e-4 and score.rotation_error < 1e-4
    assert reach.score(at_p1).success
    moved = servo.score(nearby)  # 2.1 cm off p1: the view is off by about as much
    assert not moved.success and 0.015 < moved.translation_error < 0.03
    assert moved.reward == pytest.approx(-(moved.translation_error + 0.1 * moved.rotation_error))


def test_rendering_between_steps_leaves_the_episode_as_it_is():
    """``render()`` (a viewer, a video wrapper) forms its frame with noise of its own: the
    run's frames, detections and estimates are those of the same episode without it."""
    action = np.array([0.3, -0.2, 0.1, 0.0, 0.0, 0.2], np.float32)
    episodes = []
    for look in (False, True):
        env = CdprEnv(render_mode="rgb_array", random_robot=False)
        try:
            obs, _ = env.reset(seed=7)
            seen = [obs["tag_pose"]]
            for _ in range(5):
                if look:
                    frame = env.render()
                    assert frame.shape == (480, 640, 3) and frame.std() > 1  # a real frame
                obs, *_ = env.step(action)
                seen.append(obs["tag_pose"])
        finally:
            env.close()
        episodes.append(np.array(seen))
    assert np.all(episodes[0][:, 2] > 0)  # the tag seen all along
    np.testing.assert_array_equal(episodes[1], episodes[0])
