"""The Gymnasium environment at the robot's limits: a twist beyond the winches' rate limit is
scaled down whole, a winch run past its range or a monitor fault ends the episode (never an
exception in the training loop) with a reward no policy gains by, observations stay in their
space, a reset frees the previous model, and bad input is a ValueError saying what is wrong."""

import dataclasses
import gc
import weakref

import numpy as np
import pytest

from cdpr_twin.gym import CdprEnv
from cdpr_twin.gym.env import FAILURE_REWARD
from cdpr_twin.gym.tasks import ReachPose, ServoToTag
from cdpr_twin.math.kinematics import cable_lengths
from cdpr_twin.math.se3 import so3_exp, transform
from cdpr_twin.scenario.loading import MonitorConfig, ScenarioError, load_scenario

WINCH_RATE_LIMIT = 0.5  # m/s: ACROBOT's winches (models/acrobot/robot.toml, rate_limit_m_s)


def _pose(obs: dict) -> np.ndarray:
    """The estimated pose an observation carries, [t (m), θu (rad)] → (4, 4)."""
    return transform(so3_exp(obs["pose_estimate"][3:]), obs["pose_estimate"][:3])


def test_a_twist_beyond_the_winch_limit_is_scaled_down_whole_not_an_exception():
    # 2 m/s along x needs cable rates far above 0.5 m/s: the twist is scaled, its direction kept
    env = CdprEnv(realism="ideal", truth_scale=0.0, max_speed=2.0)
    try:
        obs, _ = env.reset(seed=0)
        T = _pose(obs)
        l0 = env._setup.physics.rest_lengths
        _, _, terminated, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
        rates = (env._setup.physics.rest_lengths - l0) / env._period  # ideal winches: exact
        # the direction: nominal lengths' finite difference along x (no Jacobian code involved)
        h = 1e-6
        T_dx = T.copy()
        T_dx[0, 3] += h
        geometry = env.nominal_geometry
        direction = (cable_lengths(geometry, T_dx) - cable_lengths(geometry, T)) / h
        expected = WINCH_RATE_LIMIT * direction / np.abs(direction).max()
        np.testing.assert_allclose(rates, expected, atol=1e-6)
        assert info["rate_scale"] == pytest.approx(WINCH_RATE_LIMIT / (2 * np.abs(direction).max()))
        assert not terminated
    finally:
        env.close()


def test_a_cable_rate_scale_above_the_winch_limit_is_refused_when_built():
    with pytest.raises(
        ValueError, match=r"max_cable_rate 1.0 m/s exceeds the winches' rate limit 0.5"
    ):
        CdprEnv(action="cable_rates", max_cable_rate=1.0)


def test_pushing_to_the_limits_ends_the_episode_with_a_failure_worse_than_staying():
    """Full-speed +z twist: the platform climbs until a fault or a winch's end stops it."""
    env = CdprEnv(realism="ideal", truth_scale=0.0)
    try:
        env.reset(seed=0)
        for k in range(1, env._horizon + 1):  # noqa: B007 (k: the failed step's)
            obs, reward, terminated, truncated, info = env.step(np.r_[0, 0, 1, 0, 0, 0])
            assert env.observation_space.contains(obs)
            if terminated or truncated:
                break
        assert terminated and not truncated and not info["is_success"], info
        step_cost = -(info["translation_error"] + 0.1 * info["rotation_error"])
        left = env._horizon - k + 1  # this step and every step the episode would have had
        assert reward == pytest.approx(step_cost * left + FAILURE_REWARD)
        assert info["failure"]
    finally:
        env.close()


def test_a_monitor_fault_ends_the_episode_unless_the_scenario_continues():
    """Cables paid out at 0.1 m/s: the platform sinks to the floor (a monitor fault)."""
    scenario = load_scenario("paper_open_loop")
    seen = {}
    for on_fault in ("stop", "continue"):
        s = dataclasses.replace(scenario, monitor=MonitorConfig(on_fault=on_fault))
        env = CdprEnv(scenario=s, action="cable_rates", realism="ideal", truth_scale=0.0)
        try:
            env.reset(seed=0)
            faults, steps = [], 0
            for steps in range(1, 200):  # noqa: B007 (steps: how long it ran)
                _, _, terminated, _, info = env.step(np.ones(8, np.float32))
                faults += info.get("faults", [])
                if terminated:
                    break
            z = info["T_base_platform"][2, 3]
            seen[on_fault] = (steps, terminated, faults, info.get("failure"), z)
        finally:
            env.close()
    steps, terminated, faults, failure, z = seen["stop"]
    assert terminated and failure == faults[0] and failure.startswith("fault: "), seen["stop"]
    steps_c, terminated_c, faults_c, failure_c, z_c = seen["continue"]
    assert not terminated_c and failure_c is None and faults_c[: len(faults)] == faults
    assert steps_c > steps and z_c < z  # it went on sinking


def test_a_reset_frees_the_previous_episode_model():
    env = CdprEnv()
    gc.disable()  # a reference cycle would keep it: only the collector could free it
    try:
        env.reset(seed=0)
        old = weakref.ref(env._setup.physics)
        env.reset(seed=1)
        assert old() is None
    finally:
        gc.enable()
        env.close()


@pytest.mark.parametrize(
    ("action", "match"),
    [
        (np.ones((1, 6)), r"got shape \(1, 6\)"),
        (np.ones(3), r"6 finite numbers .* got shape \(3,\)"),
        (np.r_[np.nan, 0, 0, 0, 0, 0], "6 finite numbers"),
        (np.r_[np.inf, 0, 0, 0, 0, 0], "6 finite numbers"),
    ],
    ids=["batched", "short", "nan", "inf"],
)
def test_a_malformed_action_is_a_value_error_naming_the_shape(action, match):
    env = CdprEnv(realism="ideal")
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match=match):
            env.step(action)
    finally:
        env.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"task": 3}, "task must be 'reach' or 'servo' or a task object"),
        ({"max_speed": float("nan")}, "max_speed must be a positive number"),
        ({"max_angular_speed": -1.0}, "max_angular_speed must be a positive number"),
    ],
)
def test_bad_construction_arguments_are_value_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CdprEnv(**kwargs)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: ReachPose(horizon=-1.0), "reach: horizon must be a finite number > 0, got -1.0"),
        (lambda: ReachPose(horizon=float("nan")), "reach: horizon must be a finite number > 0"),
        (lambda: ReachPose(horizon=float("inf")), "reach: horizon must be a finite number > 0"),
        (lambda: ReachPose(goal=(0.1, 0.0, 0.3)), r"reach: goal must be 6 finite numbers"),
        (lambda: ReachPose(goal=(0.1, 0, float("nan"), 0, 0, 0)), r"goal must be 6 finite"),
        (lambda: ReachPose(position_tolerance=0.0), "position_tolerance must be a finite"),
        (lambda: ReachPose(rotation_weight=-0.1), "rotation_weight must be a finite number ≥ 0"),
        (lambda: ServoToTag(goal_view="p1"), "servo: goal_view must be 6 finite numbers"),
        (lambda: ServoToTag(rotation_tolerance_deg=True), "rotation_tolerance_deg must be"),
    ],
)
def test_a_task_with_bad_numbers_is_refused_when_made(make, match):
    # before: a negative horizon made 1-step episodes, NaN/inf raised from round(), a bad
    # goal only at the first step
    with pytest.raises(ValueError, match=match):
        make()


def test_a_reach_goal_outside_the_frame_is_refused_when_the_env_is_built():
    # truth: the frame's inner box of the robot description (1.2 m cube): x = 5 m is outside
    with pytest.raises(ValueError, match=r"reach: goal: .*outside|reach: goal: .*frame"):
        CdprEnv(task=ReachPose(goal=(5.0, 0.0, 0.3, 0.0, 0.0, 0.0)), realism="ideal")
    CdprEnv(task=ReachPose(goal=(0.1, 0.0, 0.3, 0.0, 0.0, 0.0)), realism="ideal").close()


def test_unknown_reset_options_are_refused():
    env = CdprEnv(realism="ideal")
    try:
        with pytest.raises(ValueError, match=r"reset\(\) takes no options, got \['goal'\]"):
            env.reset(seed=0, options={"goal": 1})
    finally:
        env.close()


def test_a_scaled_twist_stays_within_any_rate_limit_to_the_last_bit():
    """Scaling by limit/max|rate| can round one ulp above the limit (for limits that are not
    powers of two): the winch would refuse the command and the episode would end as a crash."""
    env = CdprEnv(realism="ideal", truth_scale=0.0, max_speed=5.0, max_angular_speed=5.0)
    try:
        env.reset(seed=0)
        rng = np.random.default_rng(1)
        for limit in (0.3, 0.7, 1.1):
            env._max_rates = np.full(8, limit)
            for a in rng.uniform(-5, 5, size=(2000, 6)):
                command, scale = env._command(a)
                fastest = np.abs(command.cable_rates).max()
                assert fastest <= limit and (scale == 1 or fastest == pytest.approx(limit))
    finally:
        env.close()


def test_a_diverging_simulation_is_scored_where_the_robot_last_was(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the cwd
    env = CdprEnv(realism="ideal", truth_scale=0.0)
    try:
        env.reset(seed=0)
        _, reward0, *_, info0 = env.step(np.zeros(6, np.float32))
        env._setup.physics.data.qvel[:] = 1e30  # MuJoCo then resets its state (qpos0)
        _, reward, terminated, _, info = env.step(np.zeros(6, np.float32))
        assert terminated and info["failure"]
        np.testing.assert_array_equal(info["T_base_platform"], info0["T_base_platform"])
        left = env._horizon - 2 + 1
        assert reward == pytest.approx(reward0 * left + FAILURE_REWARD)
    finally:
        env.close()


def test_a_stopping_fault_at_reset_ends_the_first_step_with_the_robot_unmoved():
    """Tension sensors whose range tops at 5 N: at p0 the cables read tens of newtons."""
    s = load_scenario("paper_open_loop").with_realism("ideal")
    tension = dataclasses.replace(s.realism.tension, range_max=5.0)
    realism = dataclasses.replace(s.realism, tension=tension)
    s = dataclasses.replace(s, realism=realism, monitor=MonitorConfig(on_fault="stop"))
    env = CdprEnv(scenario=s, truth_scale=0.0)
    try:
        _, info = env.reset(seed=0)
        assert info["failure"].startswith("fault: tension beyond the sensor range")
        l0 = env._setup.physics.rest_lengths
        _, _, terminated, _, step_info = env.step(np.r_[0.5, 0, 0, 0, 0, 0])
        assert terminated and step_info["failure"] == info["failure"]
        np.testing.assert_array_equal(env._setup.physics.rest_lengths, l0)  # no cable paid out
    finally:
        env.close()


def test_numpy_scalars_are_numbers_and_booleans_are_not():
    env = CdprEnv(max_speed=np.float32(0.1), max_angular_speed=np.int64(1))
    env.close()
    with pytest.raises(ValueError, match="max_speed must be a positive number, got True"):
        CdprEnv(max_speed=True)


def test_random_full_scale_twists_slacken_cables_and_on_fault_decides_what_that_does():
    """What the docs say of exploration: random ±1 twists every 40 ms slacken cables within a
    few steps; ``on_fault="continue"`` lists the fault and goes on, ``"stop"`` ends there."""
    ended = {}
    for on_fault in ("stop", "continue"):
        env = CdprEnv(on_fault=on_fault)
        env.action_space.seed(0)
        try:
            env.reset(seed=0)
            faults = []
            for steps in range(1, 21):  # noqa: B007 (steps: how long it ran)
                _, _, terminated, _, info = env.step(env.action_space.sample())
                faults += info.get("faults", [])
                if terminated:
                    break
            ended[on_fault] = (steps, terminated, faults)
        finally:
            env.close()
    steps, terminated, faults = ended["stop"]
    assert terminated and steps <= 5 and "fewer than six taut cables" in faults[0]
    steps, terminated, faults = ended["continue"]
    assert not terminated and steps == 20 and "fewer than six taut cables" in faults[0]
    with pytest.raises(ValueError, match="on_fault must be 'stop', 'continue' or None"):
        CdprEnv(on_fault="ignore")


def test_an_image_estimator_without_the_camera_names_the_envs_arguments():
    """The refusal speaks of the env's arguments, not of the command line's options."""
    with pytest.raises(ScenarioError) as err:
        CdprEnv(estimator="image", camera=False)
    words = str(err.value)
    assert "estimator=image" in words and "camera=False" in words and "--" not in words
