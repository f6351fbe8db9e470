"""The robot reports its own faults, and scenarios schedule the faults CDPR researchers test.

The monitor's verdicts are checked against an observer written here that reads MuJoCo's own
arrays (actuator forces, the platform box geom's corners, the floor geom), not the monitor's
code; event effects against runs without the event, or against MuJoCo and statics.
"""

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.cli import main
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run import runner
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.sim.events import EncoderGlitch, TensionSensorFail, WinchStall

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = ROOT / "scenarios" / "paper_open_loop.toml"
SENSOR_MAX = 75.0  # the tension sensors' range top, paper §IV-A [N]


def _runaway(tmp_path: Path, rate: float, extra: str = "") -> Path:
    """The open-loop scenario with every winch at one constant rate (tests/fault_controllers)."""
    text = OPEN_LOOP.read_text().replace('"../models/', f'"{ROOT}/models/')
    a = text.index("[controller]")
    b = text.index("\n[", a + 5)
    text = text[:a] + f'[controller]\ntype = "constant_rates"\nrate = {rate}\n' + text[b:]
    path = tmp_path / "runaway.toml"
    path.write_text('plugins = ["fault_controllers"]\n' + text + extra)
    return path


class _Observer:
    """Reads MuJoCo's arrays between physics chunks: the first time each limit is crossed."""

    def __init__(self, physics, slack_time: float) -> None:
        m, self.p, self.slack_time = physics.model, physics, slack_time
        self.box = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "platform_box")
        floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self.floor_z = float(m.geom_pos[floor][2])
        self.winches = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"winch{i + 1}_actuator")
            for i in range(8)
        ]
        self.first: dict[str, float] = {}
        self._slack_from = None

    def next_time(self) -> float:
        return self.p.time

    def fire(self, time: float) -> None:
        d, t = self.p.data, self.p.time
        if t < 1e-9:
            return
        pull = -d.actuator_force[self.winches]
        if pull.max() > SENSOR_MAX:
            self.first.setdefault("tension beyond the sensor range", t)
        taut = np.count_nonzero(pull > 0)
        if taut >= 6:
            self._slack_from = None
        elif self._slack_from is None:
            self._slack_from = t
        if self._slack_from is not None and t - self._slack_from > self.slack_time + 1e-9:
            self.first.setdefault("fewer than six taut cables", t)
        half = self.p.model.geom_size[self.box]
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        corners = d.geom_xpos[self.box] + (signs * half) @ d.geom_xmat[self.box].reshape(3, 3).T
        if corners[:, 2].min() <= self.floor_z:
            self.first.setdefault("platform on the floor", t)


@pytest.mark.parametrize(
    ("rate", "expected"), [(-0.05, "fewer than six taut cables"), (0.05, "platform on the floor")]
)
def test_reeling_in_or_paying_out_every_cable_stops_within_one_tick_of_the_limit(
    tmp_path, monkeypatch, rate, expected
):
    observers = []
    original = runner._monitor

    def watched(s, physics):
        monitor = original(s, physics)
        observer = _Observer(physics, s.model.control_period)
        observers.append(observer)
        physics.add_hook(observer)  # between chunks (20 ms on ACROBOT) …
        check = monitor.check

        def check_too():  # … and at each tick's end, as the runner asks the monitor
            observer.fire(physics.time)
            check()

        monitor.check = check_too
        return monitor

    monkeypatch.setattr(runner, "_monitor", watched)
    out = tmp_path / "out"
    code = main(
        [
            "run",
            str(_runaway(tmp_path, rate)),
            "--out",
            str(out),
            "--no-camera",
            "--duration",
            "20",
            "--realism",
            "ideal",
        ]
    )
    assert code == 3  # a fault's exit code
    summary = json.loads((out / "summary.json").read_text())
    crossed = observers[0].first
    kind, t_cross = min(crossed.items(), key=lambda kv: kv[1])  # the first limit crossed
    assert kind == expected
    assert summary["status"] == f"fault: {kind}"
    fault = summary["faults"][0]
    assert fault["kind"] == kind and abs(fault["time_s"] - t_cross) < 1e-9
    period = 0.04
    assert 0.0 <= summary["simulated_time_s"] - t_cross <= period + 1e-9  # within one tick
    ts = Timeseries.load(out / "timeseries.csv")
    assert ts.event[-1].startswith(f"fault: {kind}") and not any(ts.event[:-1])


def test_a_fault_can_be_recorded_and_the_run_continued(tmp_path):
    path = _runaway(tmp_path, 0.05, '\n[monitor]\non_fault = "continue"\n')
    s = load_scenario(path).with_realism("ideal").with_overrides(camera=False, duration=6.0)
    summary = run(s, tmp_path / "out", record_rrd=False).summary
    assert summary["status"] == "completed"
    kinds = [f["kind"] for f in summary["faults"]]
    assert kinds[0] == "platform on the floor" and summary["simulated_time_s"] > 5.99
    ts = Timeseries.load(tmp_path / "out" / "timeseries.csv")
    marked = ts.t[np.char.startswith(ts.event.astype(str), "fault")]
    assert len(marked) == len(kinds)  # each fault marked once, at its onset


def test_the_acrobot_open_loop_scenario_raises_no_fault():
    s = load_scenario(OPEN_LOOP).with_overrides(camera=False)  # as shipped: acrobot profile
    summary = run(s, None).summary
    assert summary["status"] == "done" and "faults" not in summary
    for name, e in summary["estimators"].items():  # and no sensor watch false alarm
        assert not {"encoder_mismatch", "tension_stuck"} & set(e["flags"]), (name, e["flags"])


def _events_run(tmp_path, events: str, name: str, duration: float = 3.0) -> Timeseries:
    text = OPEN_LOOP.read_text().replace('"../models/', f'"{ROOT}/models/') + events
    text += '\n[monitor]\non_fault = "continue"\n'  # the events' effects, whatever follows
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    s = load_scenario(path).with_realism("ideal").with_overrides(camera=False, duration=duration)
    run(s, tmp_path / name, record_rrd=False)
    return Timeseries.load(tmp_path / name / "timeseries.csv")


def test_winch_stall_encoder_glitch_and_sensor_failure_act_as_their_hardware_would(tmp_path):
    base = _events_run(tmp_path, "", "base")
    stall = _events_run(
        tmp_path, '\n[[events]]\nkind = "winch_stall"\nat = 1.0\ncable = 3\nuntil = 2.0\n', "stall"
    )
    t = stall.t
    during, after = (t > 1.0 + 1e-9) & (t < 2.0 - 1e-9), t > 2.0 + 1e-9
    l3 = stall.columns["length_3"]
    assert np.ptp(l3[during]) == 0.0  # the stalled drum turns not at all (exact encoders)
    assert np.ptp(base.columns["length_3"][during]) > 1e-3  # where it was commanded to move
    assert np.ptp(l3[after]) > 1e-3  # and it follows again after ``until``
    # a stalled cable drags the platform off its path (physics decides how far)
    moved = np.linalg.norm(stall.poses("true")[-1][:3, 3] - base.poses("true")[-1][:3, 3])
    assert moved > 1e-4
    glitch = _events_run(
        tmp_path, '\n[[events]]\nkind = "encoder_glitch"\nat = 1.0\ncable = 5\njump = 0.02\n', "g"
    )
    diff = glitch.matrix("length") - base.matrix("length")
    # open loop ignores encoders: the physics is unchanged, the reading is off by the jump
    np.testing.assert_array_equal(glitch.poses("true"), base.poses("true"))
    np.testing.assert_allclose(diff[glitch.t > 1.0 - 1e-9, 4], 0.02, atol=1e-12)
    assert np.all(diff[glitch.t < 1.0 - 1e-9] == 0.0) and np.all(np.delete(diff, 4, 1) == 0.0)
    fail = _events_run(
        tmp_path, '\n[[events]]\nkind = "tension_sensor_fail"\nat = 1.0\ncable = 2\n', "fail"
    )
    tau2 = fail.columns["tension_2"]
    frozen = tau2[fail.t > 1.0 - 1e-9]
    assert np.all(frozen == frozen[0]) and np.ptp(base.columns["tension_2"][base.t > 1.0]) > 0.1
    assert frozen[0] == tau2[fail.t < 1.0 - 1e-9][-1]  # frozen at its last reading
    summary = json.loads((tmp_path / "stall" / "summary.json").read_text())
    assert [(e["kind"], e["phase"]) for e in summary["events"]] == [
        ("winch_stall", "start"),
        ("winch_stall", "end"),
    ]
    # what the estimators can detect, they flag: encoders that disagree with the commanded
    # winch motion (stall, glitch), a tension sensor reading a constant; never without a fault
    flags = {run: _flags(tmp_path / run) for run in ("base", "stall", "g", "fail")}
    model = ("model_simple", "model_elastic", "model_pulley", "model_elastic_pulley")
    assert all(not f for f in flags["base"].values())
    for case in ("stall", "g"):
        assert all(flags[case][n].get("encoder_mismatch", 0) > 0 for n in ("control", *model))
    assert all(flags["fail"][n].get("tension_stuck", 0) > 0 for n in model)
    assert all("encoder_mismatch" not in flags["fail"][n] for n in model)


def _flags(out: Path) -> dict[str, dict]:
    summary = json.loads((out / "summary.json").read_text())
    paper = ("control", "model_simple", "model_elastic", "model_pulley", "model_elastic_pulley")
    return {n: e["flags"] for n, e in summary["estimators"].items() if n in paper}


@pytest.mark.parametrize(
    ("event", "field"),
    [
        ('kind = "winch_stall"\nat = 2.0\ncable = 1\nuntil = 1.0', "events[0].until"),
        ('kind = "encoder_glitch"\nat = 1.0\ncable = 1\njump = 0.0', "events[0].jump"),
        ('kind = "encoder_glitch"\nat = 1.0\ncable = 9\njump = 0.01', "events[0].cable"),
        ('kind = "tag_occlusion"\nat = 1.0\nuntil = 2.0\ncoverage = 1.5', "events[0].coverage"),
        ('kind = "tag_occlusion"\nat = 1.0\ncoverage = 0.0', "events[0].coverage"),
        ('kind = "tension_sensor_fail"\nat = 1.0\ncable = 2\nvalue = inf', "events[0].value"),
    ],
)
def test_bad_fault_events_are_errors_naming_the_field(tmp_path, event, field):
    path = tmp_path / "bad.toml"
    text = OPEN_LOOP.read_text().replace('"../models/', f'"{ROOT}/models/')
    path.write_text(text + f"\n[[events]]\n{event}\n")
    with pytest.raises(ScenarioError, match=field.replace("[", r"\[").replace("]", r"\]")):
        runner.prepare(load_scenario(path).with_overrides(camera=False)).close()


def test_event_descriptions_name_what_happened():
    assert WinchStall(at=1.0, cable=3, until=2.0).describe() == "winch_stall cable 3 until 2"
    assert EncoderGlitch(at=1.0, cable=5, jump=0.02).describe("start").endswith("jump 0.02")
    assert TensionSensorFail(at=1.0, cable=2).as_dict(1.0, "start")["value"] is None


def _equilibrium(geom, rest, broken: int | None, T_guess: np.ndarray) -> np.ndarray:
    """The pose where the cables' elastic forces (τ = E·S/l0·(L − l0), never pushing; none from
    the broken one) balance gravity: Aᵀτ = w_g with the kinematics' pulley lengths and
    Jacobian (cdpr_twin.math.kinematics, not MuJoCo)."""
    from scipy.optimize import least_squares

    from cdpr_twin.math.kinematics import cable_lengths, gravity_wrench, jacobian
    from cdpr_twin.math.se3 import pose_from_vector, vector_from_pose

    def wrench_balance(x):
        T = pose_from_vector(x)
        tau = np.maximum(0.0, geom.es / rest * (cable_lengths(geom, T, "pulley") - rest))
        if broken is not None:
            tau[broken] = 0.0
        return jacobian(geom, T, "base", "pulley").T @ tau - gravity_wrench(geom, T)

    sol = least_squares(wrench_balance, vector_from_pose(T_guess), xtol=1e-15, ftol=1e-15)
    assert np.abs(sol.fun).max() < 1e-8  # a true equilibrium [N, N·m]
    return pose_from_vector(sol.x)


def test_after_a_cable_break_the_platform_rests_where_seven_cables_statics_put_it(monkeypatch):
    from cdpr_twin.math.se3 import pose_distance

    seen: dict = {"cables": []}
    original_monitor, original_estimate = runner._monitor, runner.RunSetup.estimate

    def keep_physics(s, physics):
        seen["physics"] = physics
        return original_monitor(s, physics)

    def estimate(self, m):
        out = original_estimate(self, m)
        seen["cables"].append((m.time, {n: e.cables for n, e in out.items() if e.cables}))
        return out

    monkeypatch.setattr(runner, "_monitor", keep_physics)
    monkeypatch.setattr(runner.RunSetup, "estimate", estimate)
    s = load_scenario(ROOT / "scenarios" / "fault_cable_break.toml").with_overrides(camera=False)
    summary = run(s, None).summary  # as shipped: the acrobot profile
    assert summary["status"] == "done" and "faults" not in summary  # seven cables hold it
    assert [(e["kind"], e["cable"]) for e in summary["events"]] == [("cable_break", 2)]
    physics = seen["physics"]
    # truth: at rest after the 5 s hold, on the seven-cable equilibrium of its rest lengths
    T, rest, geom = physics.T_base_platform, physics.rest_lengths, physics.geometry
    d_t, d_r = pose_distance(_equilibrium(geom, rest, 1, T), T)
    assert d_t < 1e-7 and d_r < 1e-5, (d_t, d_r)  # 0.1 µm / 1e-5°
    # which the eight-cable equilibrium of the same rest lengths is not: the check sees the
    # break (stiff Dyneema: losing 4.8 N of pull at p0 moves the platform by ≈ 27 µm only)
    intact_t, _ = pose_distance(_equilibrium(geom, rest, None, T), T)
    assert intact_t > 100 * max(d_t, 1e-9) and intact_t > 5e-6, intact_t
    # the model-based estimators dropped the broken cable at the first tick that read it
    after = [(t, used) for t, used in seen["cables"] if t >= 26.0 - 1e-9]
    assert len(after) >= 25 and all(len(used) == 4 for _, used in after)  # 4 s, 4 estimators
    for t, used in after:
        for name, cables in used.items():
            assert 1 not in cables, (t, name, cables)
    before = [used for t, used in seen["cables"] if 25.0 < t < 26.0 - 1e-9]
    assert before and all(1 in cables for used in before for cables in used.values())


def test_a_cable_break_in_motion_can_leave_too_few_taut_cables(tmp_path):
    path = tmp_path / "break_in_motion.toml"
    text = (ROOT / "scenarios" / "fault_cable_break.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/').replace("at = 26.0 ", "at = 5.0 ")
    path.write_text(text)
    summary = run(load_scenario(path).with_overrides(camera=False), None).summary
    assert summary["status"] == "fault: fewer than six taut cables"
    assert 5.0 < summary["faults"][0]["time_s"] <= summary["simulated_time_s"] <= 5.0 + 0.2


def _camera_robot(occluder: bool):
    from cdpr_twin.sim import Sensors, build_robot

    built = build_robot(occluder=occluder)
    physics, nominal = built.physics, built.nominal
    physics.reset(paper_pose("p1"))  # the tag in the middle of the view
    return physics, Sensors(physics, nominal, tension_noise_std=0.0)


def test_the_occluding_sheet_hides_the_tag_in_the_rendered_image_and_only_then():
    _, plain_sensors = _camera_robot(False)
    physics, sensors = _camera_robot(True)
    try:
        parked = sensors.render()
        # parked under the floor, the sheet is nowhere in the frame: pixel for pixel the same
        np.testing.assert_array_equal(parked, plain_sensors.render())
        assert sensors.read().tag is not None
        physics.occlude_tag(1.0)
        covered = sensors.render()
        changed = np.any(covered != parked, axis=2)
        # it covers the tag's corners as the camera sees them, and little else of the frame
        corners = np.round(plain_sensors.read().tag.corners).astype(int)
        assert changed[corners[:, 1].clip(0, 479), corners[:, 0].clip(0, 639)].all()
        assert 0.01 < changed.mean() < 0.6
        assert sensors.read().tag is None  # the detector finds nothing: nothing was skipped
        physics.occlude_tag(0.0)
        np.testing.assert_array_equal(sensors.render(), parked)
    finally:
        sensors.close()
        plain_sensors.close()


@pytest.mark.slow
def test_pbvs_holds_still_while_the_tag_is_hidden_and_resumes_after(tmp_path):
    out = tmp_path / "occlusion"
    s = load_scenario(ROOT / "scenarios" / "fault_tag_occlusion.toml")  # as shipped: acrobot
    summary = run(s, out).summary
    assert summary["status"] == "converged" and "faults" not in summary
    for name, e in summary["estimators"].items():
        assert not {"encoder_mismatch", "tension_stuck"} & set(e["flags"]), (name, e["flags"])
    ts = Timeseries.load(out / "timeseries.csv")
    t, lost = ts.t, ts.columns["image_valid"] == 0
    hidden = (t > 3.0 + 0.2) & (t < 5.0 - 1e-9)  # (+ the camera's latency, a few frames)
    assert lost[hidden].all()  # the image estimator flags the loss …
    assert set(ts.status[hidden]) == {"tag_lost"}
    assert np.all(ts.matrix("rate")[hidden] == 0.0)  # … and PBVS commands nothing
    moved = np.linalg.norm(np.diff(ts.poses("true")[hidden][:, :3, 3], axis=0), axis=1).sum()
    assert moved < 1e-3  # the platform holds still (it swings out the stop: < 1 mm)
    back = t > 5.0 + 0.2
    assert not lost[back][:10].any() and np.any(ts.matrix("rate")[back][:10] != 0.0)
    marks = [(round(float(x), 2), e) for x, e in zip(t, ts.event, strict=True) if e]
    assert marks == [
        (3.0, "tag_occlusion until 5 coverage 1"),
        (5.0, "tag_occlusion ends until 5 coverage 1"),
    ]
    env = {**__import__("os").environ, "RERUN_ANALYTICS": "0"}
    import shutil
    import subprocess
    import sys

    rerun = shutil.which("rerun", path=str(Path(sys.executable).parent)) or "rerun"
    stats = subprocess.run(
        [rerun, "rrd", "stats", str(out / "recording.rrd")], capture_output=True, text=True, env=env
    ).stdout
    assert "/events:" in stats  # the events text log, on the run's timeline


def test_a_run_ending_with_the_tag_hidden_says_its_last_detection_is_old(tmp_path, capsys):
    # truth: the image estimator's validity in the timeseries (it is valid exactly when a tag
    # detection was read); before, the console called the 1 s old detection "final"
    out = tmp_path / "hidden_at_the_end"
    source = str(ROOT / "scenarios" / "fault_tag_occlusion.toml")
    assert main(["run", source, "--duration", "4.0", "--out", str(out)]) == 0  # hidden from 3 s
    printed = capsys.readouterr().out
    seen = json.loads((out / "summary.json").read_text())["pbvs"]["final_tag_error"]
    ts = Timeseries.load(out / "timeseries.csv")
    assert seen["detected_at_s"] == pytest.approx(ts.t[ts.columns["image_valid"] == 1].max())
    assert 2.9 < seen["detected_at_s"] < 3.3
    assert f"last tag pose error (detected): {seen['translation_m'] * 1e3:.2f} mm" in printed
    assert f"at t = {seen['detected_at_s']:.2f} s; the tag was not seen after it" in printed
