"""Inputs that used to pass silently: an unreachable PBVS goal, events a run never reaches, a
port that is not one, a damaged part of a campaign's table."""

import errno
import json
import math
import os
import signal
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import EARLIER_SUMMARY

from cdpr_twin import plugins
from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.campaign.table import flatten, load_table, read_parquet
from cdpr_twin.cli import main
from cdpr_twin.cli.tools import live_url
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.files.transaction import OutputDirError
from cdpr_twin.run.metrics import NON_FINITE_ESTIMATE
from cdpr_twin.run.runner import prepare, run
from cdpr_twin.scenario.loading import ScenarioError, load_scenario, scenario_from_data
from cdpr_twin.types import PoseEstimate

ROOT = Path(__file__).resolve().parent.parent


def _pbvs(**changes):
    source = ROOT / "scenarios" / "paper_pbvs.toml"
    data = tomllib.loads(source.read_text())
    for key, value in changes.items():
        set_dotted(data, key, value)
    return scenario_from_data(data, source)


def test_a_pbvs_goal_the_nominal_robot_cannot_reach_is_refused():
    # the tag seen 5 m away: the platform would be 5 m above it (z = 4.99 m), out of the frame
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.0, 5.0, 180, 0, 180]})
    with pytest.raises(ScenarioError, match=r"its goal .* puts the platform .* outside the frame"):
        prepare(s)


def test_the_papers_goal_is_accepted():
    prepare(_pbvs()).close()


def test_a_pbvs_goal_view_that_cuts_the_tag_is_refused_by_runs_and_campaigns(tmp_path):
    # truth: the pinhole projection of the tag's corners, by hand: at 9 cm, 4.5 cm off the
    # optical axis, the 4 cm tag's far edge sits at y = 0.065 m, v = cy + fy·0.065/0.09 > 480
    from cdpr_twin.scenario.preflight import check_task
    from cdpr_twin.sim import nominal_robot

    K = nominal_robot("acrobot").intrinsics
    assert K.cy + K.fy * (0.045 + 0.02) / 0.09 > K.height  # the far edge below the image
    assert K.cy + K.fy * (0.01 + 0.02) / 0.09 < K.height - 1  # 1 cm off: inside
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.045, 0.09, 180, 0, 180]})
    with pytest.raises(ScenarioError, match=r"goal_tag_pose_visp: .* would not see the whole tag"):
        prepare(s)
    with pytest.raises(ScenarioError, match=r"would not see the whole tag"):
        check_task(s)  # what a campaign checks of every run before the first starts
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.01, 0.09, 180, 0, 180]})
    prepare(s).close()  # 1 cm off: the whole tag in the image


def test_an_event_the_run_does_not_reach_is_listed_in_the_summary():
    s = load_scenario("fault_cable_break").with_overrides(duration=0.2, camera=False)
    summary = run(s, None).summary
    assert "events" not in summary
    [pending] = summary["events_not_reached"]
    assert (pending["kind"], pending["due_s"], pending["cable"]) == ("cable_break", 26.0, 2)


@pytest.mark.parametrize(
    "address", ["0", "99999", "host:70000", "rerun+http://host:0/proxy", "rerun://host:70000/proxy"]
)
def test_a_port_out_of_range_is_refused(address):
    with pytest.raises(ValueError, match="not a TCP port"):
        live_url(address)


def test_a_damaged_part_of_a_campaign_table_is_a_one_line_error(tmp_path):
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "part-00000.parquet").write_bytes(b"PAR1 not really parquet")
    with pytest.raises(OutputDirError, match=r"part-00000\.parquet is not a readable Parquet"):
        load_table(tmp_path)
    with pytest.raises(OutputDirError, match="delete it and run with --resume"):
        read_parquet(parts / "part-00000.parquet", ["run_id"])


def test_a_second_ctrl_c_while_a_stopped_run_saves_cannot_leave_it_half_saved(
    tmp_path, monkeypatch
):
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGINT)  # the impatient user's second Ctrl-C
        return close(self, summary, commit)

    def stop(fraction, t):
        raise KeyboardInterrupt  # the first Ctrl-C, at the first tick

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    s = load_scenario("paper_open_loop").with_overrides(duration=0.2, camera=False)
    with pytest.raises(KeyboardInterrupt):
        run(s, tmp_path / "out", progress=stop)
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["recording.rrd", "summary.json", "timeseries.csv"]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "interrupted"


def test_a_stop_before_the_run_claims_its_directory_does_not_claim_an_earlier_runs_files(
    tmp_path, monkeypatch, capsys
):
    from cdpr_twin.cli import main
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.run import runner

    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text(EARLIER_SUMMARY % "terminated")  # an earlier run's
    os.utime(out / "summary.json", (0, 0))

    def prepare(scenario):
        raise Terminated()  # SIGTERM while the robot is being built

    monkeypatch.setattr(runner, "prepare", prepare)
    assert main(["run", "paper_open_loop", "--out", str(out), "--no-camera"]) == 143
    err = capsys.readouterr().err
    assert "terminated before this run saved any output" in err and "partial" not in err


def test_an_open_loop_segment_shorter_than_a_control_tick_is_refused():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "controller.durations", [0.001, 5.0, 10.0])  # was skipped: 326 mm off p1
    with pytest.raises(ScenarioError, match=r"durations\[0\]: 0.001 s is shorter than 5 control"):
        prepare(scenario_from_data(data, source).with_overrides(camera=False))


def test_an_unknown_optional_field_lists_the_fields_it_could_be():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "realism.camera.exposure_ms", 4.0)  # was: "known fields here: none"
    with pytest.raises(ScenarioError, match=r"exposure_ms: unknown field; known .*exposure_s"):
        scenario_from_data(data, source)


def test_a_platform_above_its_exit_points_is_said_so():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "truth.exit_point_std", 1.0)  # exit points a metre off: some below p0
    s = scenario_from_data(data, source).with_overrides(camera=False)
    with pytest.raises(ScenarioError, match="is not below the lowest exit point") as error:
        prepare(s)
    assert "anchor points []" not in str(error.value)  # was: "puts anchor points [] outside"


def test_a_signal_during_a_completed_runs_save_is_delivered_once_the_files_are_whole(
    tmp_path, monkeypatch
):
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C just as the finished run saves
        return close(self, summary, commit)

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    s = load_scenario("paper_open_loop").with_overrides(duration=0.2, camera=False)
    with pytest.raises(KeyboardInterrupt):  # held off, not lost
        run(s, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"
    assert not list((tmp_path / "out").glob("*.partial")) and not (tmp_path / "out/.lock").exists()


@pytest.mark.parametrize(
    ("marker", "command"),
    [
        ("summary.json", "reproduce"),  # a single run's directory: reproduce emptied it
        ("campaign.json", "reproduce"),
        ("runs.json", "campaign"),  # a study's: a campaign overwrote its report.md
        ("runs.json", "run"),
        ("summary.json", "calibrate"),  # a run's: calibrate deleted its files
        ("campaign.json", "calibrate"),
        ("calibration.json", "run"),
        ("calibrated_robot.toml", "campaign"),
        ("calibration.json", "reproduce"),
    ],
)
def test_a_command_refuses_another_commands_directory(tmp_path, capsys, marker, command):
    from cdpr_twin.cli import main

    out = tmp_path / "out"
    out.mkdir()
    (out / marker).write_text("{}\n")
    (out / "report.md").write_text("someone's report\n")
    campaign = tmp_path / "c.toml"
    campaign.write_text(
        f'name = "c"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        '[overrides]\n"sensors.camera" = false\nduration = 0.2\n'
    )
    argv = {
        "reproduce": ["reproduce", "--out", str(out), "--duration", "0.2", "--runs-scale", "0.01"],
        "campaign": ["campaign", str(campaign), "--out", str(out)],
        "run": ["run", "paper_open_loop", "--out", str(out), "--duration", "0.2", "--no-camera"],
        "calibrate": ["calibrate", "paper_open_loop", "--out", str(out), "--poses", "12"],
    }[command]
    assert main(argv) == 2
    assert f"holds another command's outputs ({marker})" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == sorted([marker, "report.md"])
    assert (out / "report.md").read_text() == "someone's report\n"


def test_a_run_says_when_its_duration_is_rounded_or_its_viewer_cannot_open(monkeypatch):
    from cdpr_twin.cli.tools import run_notes

    s = load_scenario("paper_open_loop")
    assert run_notes(s.with_overrides(duration=1.04), spawn=False) == []
    [note] = run_notes(s.with_overrides(duration=0.059), spawn=False)
    assert note == "duration 0.059 s runs 1 control ticks of 0.04 s, 0.04 s"
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    [note] = run_notes(s, spawn=True)
    assert note.startswith("--spawn: no display")
    monkeypatch.setenv("DISPLAY", ":0")
    assert run_notes(s, spawn=True) == []


def test_a_sigterm_as_the_run_ends_says_its_outputs_are_complete(tmp_path, monkeypatch, capsys):
    from cdpr_twin.cli import main
    from cdpr_twin.recording import sinks as recorders

    close = recorders.Recorders.close

    def close_under_fire(self, summary, commit=True):
        os.kill(os.getpid(), signal.SIGTERM)  # the supervisor's stop, just as the run saves
        return close(self, summary, commit)

    monkeypatch.setattr(recorders.Recorders, "close", close_under_fire)
    out = tmp_path / "out"
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "0.2", "--no-camera"]
    assert main(argv) == 143
    assert f"terminated as the run ended (completed): its outputs in {out} are complete" in (
        capsys.readouterr().err
    )
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"


def test_a_held_signal_of_another_kind_than_the_stop_under_way_is_delivered():
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.run.interrupts import shielded, sigterm_raises

    with sigterm_raises(), pytest.raises(Terminated):  # a pool worker told to stop while it
        try:  # saves a run stopped by Ctrl-C: the SIGTERM must still end it
            raise KeyboardInterrupt
        finally:
            with shielded():
                os.kill(os.getpid(), signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt) as stop:  # a second Ctrl-C: absorbed by the first
        try:
            raise KeyboardInterrupt("first")
        finally:
            with shielded():
                os.kill(os.getpid(), signal.SIGINT)
    assert str(stop.value) == "first"


def test_model_build_into_an_unreachable_directory_is_one_line(tmp_path, monkeypatch, capsys):
    """A directory the OS will not even look at (EACCES for a non-root user; CI runs as root)."""
    from cdpr_twin.cli import main

    real_stat = os.stat

    def stat(path, *args, **kwargs):
        if os.fspath(path).endswith("locked"):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))
        return real_stat(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat)
    robot = ROOT / "models" / "acrobot" / "robot.toml"
    assert main(["model", "build", str(robot), "--out", str(tmp_path / "locked")]) == 2
    err = capsys.readouterr().err.strip()
    assert "locked: Permission denied; check its permissions" in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_a_typo_in_model_lists_the_optional_fields_too():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "model.nomnal", "x.toml")
    with pytest.raises(ScenarioError, match=r"model\.nomnal: unknown field; .*nominal"):
        scenario_from_data(data, source)


@plugins.register
class LostMidwayEstimator(Estimator):
    """The start pose, then NaN from t > 0.22 s (a plugin that loses its track)."""

    name = "lost_midway"

    def update(self, measurement, inputs=NO_INPUTS):
        self._check_reset()
        T = self._T if measurement.time <= 0.22 else np.full((4, 4), np.nan)
        return PoseEstimate(measurement.time, T)


def _strict_json(text: str):
    """Parse as RFC 8259 JSON: ``NaN``/``Infinity`` (Python's extension) raise."""

    def refuse(token):
        raise ValueError(f"{token} is not JSON (RFC 8259)")

    return json.loads(text, parse_constant=refuse)


def test_an_undefined_number_is_null_in_summary_json_and_nan_in_the_table(tmp_path, capsys):
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = f'plugins = ["{Path(__file__).stem}"]\n' + text
    path = tmp_path / "lost.toml"
    path.write_text(text.replace('passive = ["', 'passive = ["lost_midway", "', 1))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-camera", "--duration", "0.6"]) == 0
    printed = capsys.readouterr().out
    assert "lost_midway" in printed and "nan" in printed  # the table printed, not a traceback
    summary = _strict_json((out / "summary.json").read_text())  # was: a bare NaN
    lost = summary["estimators"]["lost_midway"]
    assert lost["final_translation_m"] is None and lost["final_rotation_deg"] is None
    assert lost["flags"] == {NON_FINITE_ESTIMATE: 10} and lost["invalid_updates"] == 10
    assert lost["max_translation_time_s"] <= 0.22  # over the finite estimates only
    task = {"run_id": "r", "block": "b", "name": "n", "params": {}}
    row = flatten(task, {**summary, "estimators": {"lost_midway": lost}})
    assert math.isnan(row["est.lost_midway.final_t_m"])
    assert row["est.lost_midway.max_t_m"] == lost["max_translation_m"] > 0
    assert _strict_json(row["summary"])["estimators"]["lost_midway"]["final_rotation_deg"] is None


def test_a_campaign_names_a_shipped_scenario_as_run_does(tmp_path):
    from cdpr_twin.campaign import CampaignError, load_campaign

    axes = '[[axes]]\nkey = "controller.gain"\nvalues = [0.2, 0.4]\n'
    by_path = tmp_path / "by_path.toml"
    by_path.write_text(f'name = "g"\nscenario = "{ROOT}/scenarios/paper_pbvs.toml"\n{axes}')
    by_name = tmp_path / "by_name.toml"
    by_name.write_text(f'name = "g"\nscenario = "paper_pbvs"\n{axes}')
    ids = [[t.run_id for t in load_campaign(p).tasks] for p in (by_path, by_name)]
    assert ids[0] == ids[1] and len(ids[0]) == 2  # the same runs
    by_name.write_text(f'name = "g"\nscenario = "paper_pbv"\n{axes}')
    with pytest.raises(CampaignError, match=r"scenario: no scenario named 'paper_pbv'; choose one"):
        load_campaign(by_name)


def test_ctrl_c_while_a_command_starts_is_one_line_not_a_traceback(monkeypatch, capsys):
    """Ctrl-C before a command's own handling (its imports, reading the scenario) printed a
    KeyboardInterrupt traceback."""
    from cdpr_twin.cli import main
    from cdpr_twin.scenario import loading as scenario

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scenario, "load_scenario", interrupted)
    assert main(["run", "paper_open_loop", "--duration", "0.2"]) == 130
    assert capsys.readouterr().err == "cdpr-twin run: interrupted\n"


@pytest.mark.parametrize(("shift_m", "refused"), [(0.05, False), (0.2, True)])
def test_a_nominal_description_of_another_robot_is_refused_as_such(tmp_path, shift_m, refused):
    # before: COGIRO's description as ACROBOT's nominal model was refused as "start.pose is
    # outside the wrench-feasible workspace" (COGIRO's 100-5000 N tension range at ACROBOT's
    # start pose); an exit point moved 5 cm (4x ACROBOT's 12 mm tolerance) is a belief about
    # the same robot, 20 cm (beyond 10 % of its 1.05 m span of exit points) another robot
    from cdpr_twin import resources

    cogiro = resources.models_dir() / "cogiro" / "robot.toml"
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*cogiro.*another robot"):
        prepare(_pbvs(**{"model.nominal": str(cogiro)}))
    source = resources.models_dir() / "acrobot" / "robot.toml"
    text = source.read_text().replace('"assets/', f'"{source.parent}/assets/')
    moved = text.replace("[-0.4725, -0.5275, 1.165]", f"[-0.4725, -0.5275, {1.165 + shift_m}]")
    assert moved != text
    (tmp_path / "robot.toml").write_text(moved)
    s = _pbvs(**{"model.nominal": str(tmp_path / "robot.toml")})
    if refused:
        with pytest.raises(ScenarioError, match=r"exit point 1 is 0\.2 m from the model's"):
            prepare(s)
    else:
        prepare(s).close()


def test_a_bad_nominal_description_is_named_by_its_own_key_and_a_directory_as_one(tmp_path):
    # before: both said model.file, and a directory was "not found"
    bad = tmp_path / "robot.toml"
    bad.write_text('name = "acrobot"\n')  # a description without its tables
    s = _pbvs(**{"model.nominal": str(bad)})
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*robot\.toml"):
        prepare(s)
    data = tomllib.loads((ROOT / "scenarios" / "paper_open_loop.toml").read_text())
    data["model"] = {"file": str(tmp_path)}
    with pytest.raises(ScenarioError, match=r": model\.file: model file .* is a directory"):
        prepare(scenario_from_data(data, ROOT / "scenarios" / "paper_open_loop.toml"))


def test_a_file_saved_with_a_byte_order_mark_reads_as_without_it(tmp_path):
    # before: "not valid TOML: Invalid statement (at line 1, column 1)", the mark invisible
    # in an editor; now a scenario, a robot description and a campaign read as without it
    from dataclasses import replace

    from cdpr_twin import resources
    from cdpr_twin.campaign import load_campaign
    from cdpr_twin.robot.description import load_robot

    def marked(source: Path, to: Path, text: str | None = None) -> Path:
        to.parent.mkdir(exist_ok=True)
        to.write_text("\ufeff" + (text or source.read_text(encoding="utf-8")), encoding="utf-8")
        assert to.read_bytes()[:3] == b"\xef\xbb\xbf"
        return to

    scenario = ROOT / "scenarios" / "paper_open_loop.toml"
    read = load_scenario(marked(scenario, tmp_path / "scenarios" / scenario.name))
    assert repr(read) == repr(replace(load_scenario(scenario), source=read.source))
    robot = resources.models_dir() / "acrobot" / "robot.toml"
    (tmp_path / "assets").symlink_to(robot.parent / "assets")  # its tag texture, beside it
    read = load_robot(marked(robot, tmp_path / "robot.toml"))
    plain = load_robot(robot)
    assert read.name == plain.name and read.mass == plain.mass
    assert np.array_equal(read.exit_points, plain.exit_points)
    campaign = ROOT / "campaigns" / "paper_study.toml"
    text = campaign.read_text(encoding="utf-8").replace("../scenarios/", f"{ROOT}/scenarios/")
    tasks = load_campaign(marked(campaign, tmp_path / "campaigns" / "c.toml", text)).tasks
    assert [t.run_id for t in tasks] == [t.run_id for t in load_campaign(campaign).tasks]


def test_a_directory_given_for_a_description_is_called_a_directory(tmp_path):
    # before: "not found" for a directory that is there (model.nominal, a robot description)
    from cdpr_twin.robot.description import RobotError, load_robot

    with pytest.raises(ScenarioError, match=r": model\.nominal: .* is a directory; give a robot"):
        _pbvs(**{"model.nominal": str(tmp_path)})
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*nothing\.toml not found"):
        _pbvs(**{"model.nominal": str(tmp_path / "nothing.toml")})
    with pytest.raises(RobotError, match=r": a directory, not a robot description; give its"):
        load_robot(tmp_path)
    with pytest.raises(RobotError, match=r"nothing\.toml: robot description not found"):
        load_robot(tmp_path / "nothing.toml")
