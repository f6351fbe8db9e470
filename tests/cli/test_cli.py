"""The `cdpr-twin` command: bad input gets a one-line error naming file and field, exit code 2,
no output left behind; Ctrl-C leaves valid, flushed partial outputs."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cdpr_twin.scenario.loading import load_scenario

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()


def _cli(*args: str, cwd: Path, encoding: str = "utf-8") -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONIOENCODING": encoding}
    return subprocess.run(
        [sys.executable, "-m", "cdpr_twin", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=300,
    )


def _scenario(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(
        text.replace(
            'file = "../models/acrobot/scene.xml"',
            f'file = "{ROOT / "models" / "acrobot" / "scene.xml"}"',
        )
    )
    return path


BAD = {
    "unknown_estimator": (('in_loop = "control"', 'in_loop = "kalman"'), "estimators.in_loop"),
    "unknown_controller": (('type = "open_loop"', 'type = "mpc"'), "controller.type"),
    "missing_field": (("duration = 25.0", ""), "duration: missing"),
    "wrong_type": (("duration = 25.0", 'duration = "25 s"'), "duration: must be a finite number"),
    "wrong_unit": (
        ("tension_noise_std = 0.24", "tension_noise_std = -0.24"),
        "sensors.tension_noise_std",
    ),
    "unknown_field": (("seed = 1 ", "seeds = 1 "), "seeds: unknown field"),
    "waypoint_outside": (
        ("[0.284, -0.197, 0.25, 0, 0, 0]", "[0.284, -0.197, 1.5, 0, 0, 0]"),
        "controller.waypoints[1]",
    ),
    "period_not_whole_steps": (
        ("timestep = 0.0005", "timestep = 0.0007"),
        "model.control_rate: the control period",
    ),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_bad_scenario_is_a_one_line_error_with_exit_code_2(case, tmp_path):
    (old, new), field = BAD[case]
    assert old in OPEN_LOOP
    path = _scenario(tmp_path, OPEN_LOOP.replace(old, new, 1))
    out = tmp_path / "out"
    proc = _cli("run", str(path), "--out", str(out), "--no-camera", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(path) in lines[0] and field in lines[0], lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_negative_seed_override(tmp_path):
    proc = _cli(
        "run",
        str(ROOT / "scenarios" / "paper_open_loop.toml"),
        "--seed",
        "-1",
        "--out",
        str(tmp_path / "out"),
        cwd=tmp_path,
    )
    assert proc.returncode == 2 and "--seed" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_missing_and_malformed_scenario_files(tmp_path):
    proc = _cli("run", str(tmp_path / "nope.toml"), cwd=tmp_path)
    assert proc.returncode == 2 and "scenario file not found" in proc.stderr
    proc = _cli("run", str(tmp_path), cwd=tmp_path)  # before: "scenario file not found"
    assert proc.returncode == 2 and ": a directory, not a scenario file" in proc.stderr
    bad = tmp_path / "broken.toml"
    bad.write_text("name = [unclosed\n")
    proc = _cli("run", str(bad), cwd=tmp_path)
    assert proc.returncode == 2 and "not valid TOML" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_ctrl_c_leaves_valid_flushed_partial_outputs(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cdpr_twin",
            "run",
            str(ROOT / "scenarios" / "paper_pbvs.toml"),
            "--out",
            str(out),
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a shell that started us in the background may ignore SIGINT, and Python keeps an
        # ignored SIGINT ignored: give the child the default disposition, as a terminal would
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    partial = out / "timeseries.csv.partial"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # wait until the run is under way
        if partial.exists() and partial.read_text().count("\n") > 30:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    rows = (out / "timeseries.csv").read_text().splitlines()
    assert summary["ticks_recorded"] == len(rows) - 1 > 30
    header = rows[0].split(",")
    assert all(len(r.split(",")) == len(header) for r in rows[1:])  # no torn last line
    assert (out / "recording.rrd").stat().st_size > 0
    assert not list(out.glob("*.partial"))
    rerun = Path(sys.executable).parent / "rerun"
    check = subprocess.run(
        [str(rerun), "rrd", "verify", str(out / "recording.rrd")],
        capture_output=True,
        text=True,
        env={**env, "RERUN_ANALYTICS": "0"},
    )
    assert check.returncode == 0, check.stderr


@pytest.mark.parametrize("encoding", ["utf-8", "ascii"])
def test_run_prints_the_table_and_writes_outputs(tmp_path, encoding):
    """On an ASCII terminal Δ and ° come out escaped (before: a traceback and exit 1 after
    the run's files were written)."""
    out = tmp_path / "out"
    proc = _cli(
        "run",
        str(ROOT / "scenarios" / "paper_open_loop.toml"),
        "--out",
        str(out),
        "--duration",
        "1",
        "--no-camera",
        "--seed",
        "3",
        cwd=tmp_path,
        encoding=encoding,
    )
    assert proc.returncode == 0, proc.stderr
    delta = "Δ" if encoding == "utf-8" else "\\u0394"
    assert "model_elastic_pulley" in proc.stdout and f"max {delta}t [mm]" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 3 and summary["overrides"]["camera"] is False
    assert "image" not in summary["estimators"]
    assert {p.name for p in out.iterdir()} == {"recording.rrd", "timeseries.csv", "summary.json"}


@pytest.mark.parametrize("unbuffered", [False, True])
def test_a_reader_that_goes_away_ends_the_command_quietly_with_sigpipes_status(unbuffered):
    # before: `cdpr-twin scenarios list | head -1` printed a BrokenPipeError traceback, exit 1;
    # then still so with PYTHONUNBUFFERED=1 (as in many containers): no buffer left to flush
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # as in a shell
    env.update({"PYTHONUNBUFFERED": "1"} if unbuffered else {})
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdpr_twin", "scenarios", "list"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    proc.stdout.close()  # the reader is gone before the command writes a line
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141, err
    assert err == ""


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
