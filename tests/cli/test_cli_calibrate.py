"""``cdpr-twin calibrate`` refuses bad input in one line before any work, never destroys its own
input and leaves nothing running when killed.

Before: ``--out`` naming the folder of the scenario's ``[model] nominal`` (refining a
calibration in place) cleared that folder first — the description the calibration
starts from and its report were gone, and the command then said "robot description not
found"; and a calibration killed with SIGKILL left its two worker processes recording for
minutes, holding the command's output pipe open.
"""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import children, group_alive, outlived_by_its_group, pool_threads

from cdpr_twin import cli
from cdpr_twin.calibrate.solver import CalibrationError
from cdpr_twin.cli import main

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
START = "pose = [0.112, -0.032, 0.301, -12, -10, 0]"


def test_out_on_the_nominal_descriptions_folder_is_refused_and_nothing_is_touched(
    tmp_path, capsys, monkeypatch
):
    from cdpr_twin.cli import calibrate as cli_calibrate

    folder = tmp_path / "cal"
    shutil.copytree(ROOT / "docs" / "calibration" / "robot_19", folder)
    desc = folder / "calibrated_robot.toml"  # its texture named from where it was written
    desc.write_text(desc.read_text().replace('"../../../models/', f'"{ROOT}/models/'))
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    assert "\nnominal" not in text
    text = text.replace("[model]\n", '[model]\nnominal = "cal/calibrated_robot.toml"\n', 1)
    scenario = tmp_path / "s.toml"
    scenario.write_text(text)
    assert main(["calibrate", str(scenario), "--out", str(folder), "--poses", "12"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert (
        f"--out {folder}: this calibration would replace {folder / 'calibrated_robot.toml'}" in err
    )
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # untouched
    # the same scenario into another folder passes every check (the long part stubbed out)
    monkeypatch.setattr(cli_calibrate, "_guarded", lambda *args: 0)
    assert main(["calibrate", str(scenario), "--out", str(tmp_path / "new"), "--poses", "12"]) == 0


def test_a_calibration_killed_without_cleanup_leaves_no_worker_recording(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "cdpr_twin",
        "calibrate",
        "paper_open_loop",
        "--out",
        str(tmp_path / "out"),
        "--poses",
        "12",
        "--workers",
        "2",
    ]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "MUJOCO_GL": "egl"},
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while len(children(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)  # the pool's workers (and its resource tracker) have spawned
        assert proc.poll() is None and len(children(proc.pid)) >= 2
        time.sleep(2.0)  # the workers imported the package and record
        alive = outlived_by_its_group(proc)
    finally:
        if group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not alive, "a worker kept recording after its calibration was killed"


def test_a_failed_recording_waits_for_its_pools_thread_before_the_error_leaves(monkeypatch):
    # Before (CI, exit 143 then a trace): a SIGTERMed calibration ended its workers and left
    # the pool's thread closing its wake-up pipe while the interpreter exited; Python's exit
    # hook wrote to that pipe: "Exception ignored in <module 'threading'> … OSError: [Errno 9]
    # Bad file descriptor" after "terminated". The pool's thread is made slow to close its pipe
    # (0.5 s), so a stop that does not wait for it is seen every time. Truth: Python's own list
    # of live threads.
    import multiprocessing
    from concurrent.futures import process

    import pytest

    from cdpr_twin.calibrate.acquire import _in_processes

    closing = process._ExecutorManagerThread.join_executor_internals

    def slow(self):
        time.sleep(0.5)
        closing(self)

    monkeypatch.setattr(process._ExecutorManagerThread, "join_executor_internals", slow)
    items = [(i, []) for i in range(4)]
    with pytest.raises(AttributeError):  # no scenario: each segment fails in its worker
        _in_processes(items, 2, None, 1)
    assert pool_threads() == []
    assert multiprocessing.active_children() == []


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


@pytest.fixture
def no_recording(monkeypatch):
    """Recording (a worker process, or in this one) fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError("the recording started before the input was checked")

    monkeypatch.setattr("cdpr_twin.calibrate.acquire.ProcessPoolExecutor", refuse)
    monkeypatch.setattr("cdpr_twin.calibrate.pipeline.record", refuse)


def test_calibrate_start_outside_the_frame_is_refused_as_run_refuses_it(
    tmp_path, no_recording, capsys
):
    bad = tmp_path / "bad.toml"
    bad.write_text(OPEN_LOOP.replace(START, "pose = [0, 0, 5.0, 0, 0, 0]"))
    out = tmp_path / "cal"
    args = ["calibrate", str(bad), "--poses", "12", "--workers", "2", "--out", str(out)]
    assert cli.main(args) == 2
    err = _error(capsys)
    assert "start.pose" in err and "outside the frame" in err
    assert not out.exists()
    assert cli.main(["run", str(bad), "--out", str(tmp_path / "run")]) == 2
    assert _error(capsys).split("error: ", 1)[1] == err.split("error: ", 1)[1]


@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--frames", "0", "--frames (readings averaged per pose) must be within 1…1000, got 0"),
        ("--frames", "-1", "--frames (readings averaged per pose) must be within 1…1000, got -1"),
        ("--frames", "1001", "must be within 1…1000, got 1001"),
        ("--poses", "11", "--poses must be within 12…10000, got 11"),
        ("--poses", "100000000", "--poses must be within 12…10000"),  # was: 900 MB, no word
    ],
)
def test_calibrate_counts_out_of_range_are_refused(
    option, value, says, tmp_path, no_recording, capsys
):
    out = tmp_path / "cal"
    args = ["calibrate", "paper_open_loop", "--poses", "12", option, value]
    assert cli.main([*args, "--out", str(out)]) == 2
    assert says in _error(capsys)
    assert not out.exists()


def test_calibrate_failing_before_writing_leaves_no_directory_it_made(
    tmp_path, monkeypatch, capsys
):
    def fail(*args, **kwargs):
        raise CalibrationError("the tag was never detected at the excitation poses")

    monkeypatch.setattr("cdpr_twin.calibrate.pipeline.calibrate", fail)
    out = tmp_path / "runs" / "cal"
    assert cli.main(["calibrate", "paper_open_loop", "--poses", "12", "--out", str(out)]) == 2
    assert "never detected" in _error(capsys)
    assert not (tmp_path / "runs").exists()  # neither it nor the parent it made
    mine = tmp_path / "mine"  # a directory the user made is kept, with what it held
    mine.mkdir()
    (mine / "notes.txt").write_text("x")
    assert cli.main(["calibrate", "paper_open_loop", "--poses", "12", "--out", str(mine)]) == 2
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
