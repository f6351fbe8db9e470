"""One tick, one object: the runner and the Gymnasium environment drive the same episode.

Truth: the runner's own ``timeseries.csv`` (floats at 17 digits, exact) read back from disk,
against the true poses the environment reports for the same commands.
"""

import dataclasses
import math

import numpy as np

from cdpr_twin.gym.env import CdprEnv
from cdpr_twin.math.se3 import quat_wxyz_from_matrix
from cdpr_twin.recording.timeseries import load_timeseries
from cdpr_twin.run.episode import Episode
from cdpr_twin.run.runner import prepare, run
from cdpr_twin.scenario.loading import load_scenario

DURATION = 0.48
"""Simulated seconds compared [s] (12 ticks of 40 ms)."""


def _true_rows(columns: dict) -> np.ndarray:
    return np.stack([columns[f"true_{k}"] for k in ("x", "y", "z", "qw", "qx", "qy", "qz")], 1)


def test_the_environment_fed_the_runners_commands_follows_its_truth_to_the_last_bit(tmp_path):
    env = CdprEnv(
        scenario="paper_open_loop",
        action="cable_rates",
        camera=False,
        random_robot=False,
        max_cable_rate=0.0625,
    )
    try:
        _, info = env.reset(seed=7)
        # the run the environment's episode is: its scenario with the run seed it drew
        s = dataclasses.replace(env.scenario, seed=info["run_seed"])
        out = tmp_path / "run"
        run(s.with_overrides(duration=DURATION), out, record_rrd=False)
        c = load_timeseries(out / "timeseries.csv").columns
        n = env.action_space.shape[0]  # one rate per cable
        rates = np.stack([c[f"rate_{i + 1}"] for i in range(n)], 1)[1:]
        assert len(rates) == round(DURATION / s.model.control_period)
        # a power-of-two scale: rate / scale × scale is the rate itself, bit for bit
        assert 0 < np.abs(rates).max() <= 0.0625
        poses = [info["T_base_platform"]]
        for r in rates:
            _, _, terminated, truncated, info = env.step(r / 0.0625)
            assert not (terminated or truncated), info
            poses.append(info["T_base_platform"])
    finally:
        env.close()
    T = np.array(poses)
    mine = np.concatenate([T[:, :3, 3], quat_wxyz_from_matrix(T[:, :3, :3])], axis=1)
    assert len(c["t"]) == len(T) and math.isclose(c["t"][-1], DURATION)
    assert np.array_equal(mine, _true_rows(c))  # the same floats: the same ticks


def test_an_event_is_reported_in_the_tick_whose_read_first_sees_it(tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    text = (root / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{root}/models/')
    path = tmp_path / "cut.toml"
    path.write_text(text + '\n[[events]]\nkind = "cable_break"\nat = 0.101\ncable = 3\n')
    s = load_scenario(path).with_overrides(camera=False, duration=0.3)
    setup = prepare(s)
    kept = []

    class Keep:
        def add(self, tick):
            kept.append(tick)

    try:
        episode = Episode(setup, [Keep()])
        first = episode.reset()
        ticks = [first] + [episode.step() for _ in range(8)]
    finally:
        setup.close()
    assert kept == ticks  # every tick went to the sink, in order
    assert first.command is None and all(t.command is not None for t in ticks[1:])
    with_event = [t for t in ticks if t.events]
    [tick] = with_event
    [(time, event, phase)] = tick.events
    # fired inside the physics, between two steps, within the tick that first reads after it
    assert phase == "start" and event.cable == 3 and 0.101 - 1e-9 <= time <= tick.time
    before = ticks[ticks.index(tick) - 1]
    assert before.time < 0.101 and tick.marks == ("cable_break cable 3",)
    # truth beside the readings: the broken cable pulls nothing from that tick on
    assert before.tensions[2] > 1.0 and tick.tensions[2] == 0.0


def _open_loop_setup():
    return prepare(load_scenario("paper_open_loop").with_overrides(camera=False, duration=0.2))


def test_a_step_is_its_two_halves_advance_then_read():
    # truth: a second, identical run driven by the halves; every reading and true value equal
    whole, halves = _open_loop_setup(), _open_loop_setup()
    try:
        stepped, split = Episode(whole), Episode(halves)
        a, b = [stepped.reset()], [split.reset()]
        for _ in range(4):
            a.append(stepped.step())
            in_loop = b[-1].estimates[halves.scenario.estimators.in_loop]
            k = len(b) - 1
            command = halves.controller.command(
                k * split.period, split.period, in_loop, b[-1].measurement
            )
            split.advance(split.period, command.cable_rates)
            b.append(split.read(command))
    finally:
        whole.close()
        halves.close()
    for x, y in zip(a, b, strict=True):
        assert x.time == y.time
        np.testing.assert_array_equal(x.T_base_platform, y.T_base_platform)
        np.testing.assert_array_equal(x.measurement.cable_lengths, y.measurement.cable_lengths)
        np.testing.assert_array_equal(x.measurement.tensions, y.measurement.tensions)
        for name in x.estimates:
            np.testing.assert_array_equal(
                x.estimates[name].T_base_platform, y.estimates[name].T_base_platform
            )
    assert a[-1].time > a[0].time  # it moved on


def test_an_episode_without_a_controller_asks_for_each_command():
    setup = _open_loop_setup()
    try:
        setup.controller = None
        episode = Episode(setup)
        episode.reset()
        t0 = setup.physics.time
        try:
            episode.step()
        except ValueError as exc:
            assert "pass each tick's command" in str(exc)
        else:
            raise AssertionError("a step without a command nor a controller went on")
        assert setup.physics.time == t0  # nothing moved
        tick = episode.step(episode.last.command or _rest(setup))
        assert tick.plan is None and tick.time > t0
    finally:
        setup.close()


def _rest(setup):
    from cdpr_twin.types import Command

    return Command(np.zeros(setup.physics.n_cables), np.zeros(6))


def test_a_calibration_moves_and_reads_the_robot_only_through_an_episode(monkeypatch):
    # truth: every call of the physics' advance and of the sensors' read, counted where they
    # happen, against those made from inside the Episode's own methods
    from cdpr_twin.calibrate.acquire import record
    from cdpr_twin.calibrate.excitation import excitation_poses
    from cdpr_twin.sim import Physics, Sensors, build_robot

    inside = [0]
    counts = {"advance": [0, 0], "read": [0, 0]}

    def counted(owner, name, key):
        original = getattr(owner, name)

        def wrapper(*args, **kwargs):
            counts[key][0] += 1
            counts[key][1] += inside[0] > 0
            return original(*args, **kwargs)

        monkeypatch.setattr(owner, name, wrapper)

    def inside_episode(name):
        original = getattr(Episode, name)

        def wrapper(*args, **kwargs):
            inside[0] += 1
            try:
                return original(*args, **kwargs)
            finally:
                inside[0] -= 1

        monkeypatch.setattr(Episode, name, wrapper)

    counted(Physics, "advance", "advance")
    counted(Sensors, "read", "read")
    for name in ("advance", "read"):
        inside_episode(name)
    s = load_scenario("paper_open_loop")
    nominal = build_robot(s.model.file).nominal
    poses = excitation_poses(
        nominal.geometry, nominal.T_base_tag, nominal.intrinsics, nominal.tag_size, 2, s.start_pose
    )
    rec = record(s, poses[:1], frames=2, workers=1)
    assert rec.obs.n_poses == 2  # the homed robot's readings, then the pose's
    n_advance, via_episode = counts["advance"]
    assert n_advance > 10 and via_episode == n_advance  # the move, rests and tightening
    n_read, via_episode = counts["read"]
    assert n_read >= 4 and via_episode == n_read  # frames at two poses, the tightening's
