"""Timed events act through the physics hooks: a cable broken at t = 1 s stays broken."""

import json

import mujoco
import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.sim import build_robot
from cdpr_twin.sim.events import CableBreak, EventSchedule

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()


def _mujoco_force(physics, cable: int) -> float:
    """Cable force straight from MuJoCo (the winch actuator's output), by name."""
    aid = mujoco.mj_name2id(physics.model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"winch{cable}_actuator")
    return float(physics.data.actuator_force[aid])


@pytest.mark.parametrize("break_time", [1.0, 1.0127])  # on a tick, and between two steps
def test_a_broken_cable_stays_slack_across_swivel_and_stiffness_refreshes(break_time):
    physics = build_robot(align_every=10).physics
    physics.reset(paper_pose("p1"))
    schedule = EventSchedule((CableBreak(at=break_time, cable=7),), physics, sensors=None)
    physics.add_hook(schedule)
    assert _mujoco_force(physics, 7) < -10.0  # taut (MuJoCo's actuator force is a pull: negative)
    forces, times, others = [], [], []
    for _ in range(50):  # 2 s in 40 ms ticks of 80 steps: refreshes every 10 steps, as in runs
        physics.advance(0.04, np.zeros(8))
        forces.append(_mujoco_force(physics, 7))
        times.append(physics.time)
        others.append(np.delete(physics.tensions, 6).max())
    forces, times = np.array(forces), np.array(times)
    fired_at = schedule.fired[0][0]
    # it fired between the steps where its time falls, not at the next tick or refresh
    assert abs(fired_at - break_time) <= 0.5 * physics.timestep
    assert np.all(forces[times < break_time - 1e-9] < -5.0)
    # from then on the force is exactly zero, across the ~200 refreshes that follow (which
    # recompute every other cable's stiffness and every swivel)
    # (a tick ending exactly at the break time reads before it: the physics fires it before
    # the next step; the runner fires it before that tick's read, see the scenario test)
    after = forces[times > break_time + 1e-9]
    assert len(after) >= 24 and np.all(after == 0.0)
    # while the other seven keep pulling (the platform swings on them)
    assert np.max(np.array(others)[times > break_time + 1e-9]) > 5.0
    # the physics answers: the platform, hanging from seven cables, has moved
    assert np.linalg.norm(physics.T_base_platform[:3, 3] - paper_pose("p1")[:3, 3]) > 1e-3


def test_a_cable_break_from_a_scenario_file(tmp_path):
    text = OPEN_LOOP.replace("duration = 25.0", "duration = 2.0")
    text += '\n[[events]]\nkind = "cable_break"\nat = 1.0\ncable = 8\n'
    text = text.replace("tension_noise_std = 0.24", "tension_noise_std = 0.0")
    path = tmp_path / "break.toml"
    path.write_text(text.replace('"../models/', f'"{ROOT}/models/'))
    scenario = load_scenario(path).with_realism("ideal").with_overrides(camera=False)
    assert scenario.events == (CableBreak(at=1.0, cable=8),)
    run(scenario, tmp_path / "out", record_rrd=False)
    ts = Timeseries.load(tmp_path / "out" / "timeseries.csv")
    tau8 = ts.columns["tension_8"]
    assert np.all(tau8[ts.t < 1.0 - 1e-9] > 2.0)
    # the reading at t = 1.0 s itself sees the break: it fired before that tick's read
    assert np.all(tau8[ts.t > 1.0 - 1e-9] == 0.0)  # noise-free sensor: exactly no force
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["events"] == [
        {
            "time_s": pytest.approx(1.0, abs=1e-9),
            "kind": "cable_break",
            "phase": "start",
            "at": 1.0,
            "cable": 8,
        }
    ]
    # without the event the same run keeps cable 8 taut, and ends elsewhere
    intact = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").with_realism("ideal")
    intact = intact.with_overrides(camera=False, duration=2.0)
    intact_summary = run(intact, None).summary
    assert intact_summary["final_tensions_n"][7] > 1.0
    moved = np.subtract(intact_summary["final_pose"][:3], ts.poses("true")[-1][:3, 3])
    assert np.linalg.norm(moved) > 1e-3


@pytest.mark.parametrize(
    ("event", "field"),
    [
        ('kind = "cable_break"\nat = 1.0\ncable = 9', "events[0].cable: must be in 1…8"),
        (
            'kind = "cable_break"\nat = 2.0\ncable = 2\n[[events]]\nkind = "cable_break"\n'
            "at = 1.0\ncable = 9",
            "events[1].cable: must be in 1…8",
        ),
        ('kind = "cable_break"\nat = -1.0\ncable = 2', "events[0].at"),
        ('kind = "meteor"\nat = 1.0', "events[0].kind"),
        ('kind = "cable_break"\ncable = 2', "events[0].at: missing"),
        ('kind = "cable_break"\nat = 1.0\ncable = 2\nwhen = 3', "events[0].when: unknown field"),
    ],
)
def test_bad_events_are_errors_naming_the_field(tmp_path, event, field):
    path = tmp_path / "bad.toml"
    text = OPEN_LOOP.replace('"../models/', f'"{ROOT}/models/') + f"\n[[events]]\n{event}\n"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=field.replace("[", r"\[").replace("]", r"\]")):
        from cdpr_twin.run.runner import prepare

        prepare(load_scenario(path).with_overrides(camera=False)).close()


def test_a_tag_occlusion_without_a_camera_is_dropped_and_said_and_changes_nothing(tmp_path):
    # before: accepted, reported as fired in summary.json, and its occluder body
    # moved the physics by ~1e-12 m. Truth: the same run without the event, byte for byte
    text = OPEN_LOOP.replace("duration = 25.0", "duration = 1.0")
    text = text.replace('"../models/', f'"{ROOT}/models/')
    (tmp_path / "plain.toml").write_text(text)
    text += '\n[[events]]\nkind = "tag_occlusion"\nat = 0.5\nuntil = 0.7\n'
    (tmp_path / "hidden.toml").write_text(text)
    for name in ("plain", "hidden"):
        s = load_scenario(tmp_path / f"{name}.toml").with_overrides(camera=False)
        run(s, tmp_path / name, record_rrd=False)
    summary = json.loads((tmp_path / "hidden" / "summary.json").read_text())
    assert summary["overrides"]["dropped_events"] == ["events[0]"]
    assert "events" not in summary  # nothing fired
    assert (tmp_path / "hidden" / "timeseries.csv").read_bytes() == (
        tmp_path / "plain" / "timeseries.csv"
    ).read_bytes()


def test_an_event_the_run_does_not_reach_is_listed_in_the_summary():
    s = load_scenario("fault_cable_break").with_overrides(duration=0.2, camera=False)
    summary = run(s, None).summary
    assert "events" not in summary
    [pending] = summary["events_not_reached"]
    assert (pending["kind"], pending["due_s"], pending["cable"]) == ("cable_break", 26.0, 2)
