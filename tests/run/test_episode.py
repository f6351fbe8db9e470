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
