"""Output transactions: one run owns its directory, final names belong to one run and
are whole, ``summary.json`` is the commit marker, SIGTERM is handled like Ctrl-C, a failed write
is a one-line error that leaves ``*.partial`` only; bad ``--out``/scenario/duration: exit 2."""

import errno
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EARLIER_SUMMARY

from cdpr_twin.cli import main
from cdpr_twin.files.transaction import LOCK_NAME, OutputDir, OutputDirError
from cdpr_twin.recording.timeseries import TimeseriesWriter

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = ROOT / "scenarios" / "paper_open_loop.toml"
FINAL = {"timeseries.csv", "recording.rrd", "summary.json"}


def _scenario(tmp_path: Path, durations: tuple[float, float, float]) -> Path:
    """The open-loop scenario with slower segments (a longer run), the model by absolute path."""
    text = OPEN_LOOP.read_text()
    old = "durations = [10.0, 5.0, 10.0]"
    assert old in text
    text = text.replace(old, f"durations = {list(durations)}").replace(
        'file = "../models/acrobot/scene.xml"',
        f'file = "{ROOT / "models" / "acrobot" / "scene.xml"}"',
    )
    path = tmp_path / f"slow_{int(sum(durations))}.toml"
    path.write_text(text)
    return path


def _start(scenario: Path, out: Path, *args: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "cdpr_twin", "run", str(scenario), "--out", str(out)]
    return subprocess.Popen(
        [*command, "--no-camera", *args],
        cwd=out.parent,
        env={**os.environ, "MUJOCO_GL": "egl"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cdpr_twin", "run", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "MUJOCO_GL": "egl"},
        timeout=300,
    )


def _wait_under_way(proc: subprocess.Popen, out: Path, rows: int = 50) -> None:
    """Wait until the run has written ``rows`` CSV rows (it holds the lock by then)."""
    partial = out / "timeseries.csv.partial"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if partial.exists() and partial.read_text().count("\n") > rows:
            assert (out / LOCK_NAME).exists()
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    pytest.fail("the run did not get under way")


def _check_csv(path: Path) -> int:
    """Header plus rows of equal length (no torn or foreign line); returns the row count."""
    rows = path.read_text().splitlines()
    width = len(rows[0].split(","))
    assert all(len(r.split(",")) == width for r in rows[1:])
    return len(rows) - 1


def _one_error_line(stderr: str) -> str:
    assert "Traceback" not in stderr
    lines = [ln for ln in stderr.splitlines() if ln.startswith("cdpr-twin:")]
    assert len(lines) == 1, stderr
    return lines[0]


def test_a_second_run_on_a_locked_directory_is_refused(tmp_path):
    out = tmp_path / "out"
    first = _start(_scenario(tmp_path, (40.0, 20.0, 40.0)), out, "--duration", "100")
    try:
        _wait_under_way(first, out)
        second = _cli(str(OPEN_LOOP), "--out", str(out), "--no-camera", cwd=tmp_path)
        assert first.poll() is None, "the first run ended too soon for this test"
    finally:
        _, err = first.communicate(timeout=300)
    assert second.returncode == 2, second.stderr
    line = _one_error_line(second.stderr)
    assert str(out) in line and f"pid {first.pid}" in line
    assert first.returncode == 0, err
    assert {p.name for p in out.iterdir()} == FINAL
    summary = json.loads((out / "summary.json").read_text())
    # (≥ 50: the signal may land right after the second batch of 25 rows was written)
    assert summary["ticks_recorded"] == _check_csv(out / "timeseries.csv") >= 50


def test_sigterm_completes_the_outputs_marked_terminated(tmp_path):
    out = tmp_path / "out"
    proc = _start(_scenario(tmp_path, (200.0, 100.0, 200.0)), out, "--duration", "500")
    _wait_under_way(proc, out)
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 143, stderr
    assert "terminated" in _one_error_line(stderr)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "terminated"
    # (≥ 50: the signal may land right after the second batch of 25 rows was written)
    assert summary["ticks_recorded"] == _check_csv(out / "timeseries.csv") >= 50
    assert {p.name for p in out.iterdir()} == FINAL  # no *.partial, no lock


def test_sigkill_leaves_no_final_name_then_a_fresh_run_takes_the_stale_lock(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    for name in FINAL:  # an earlier run's complete outputs
        (out / name).write_text(EARLIER_SUMMARY % "completed")
    (out / "recording.rrd.partial").write_text("older still")
    proc = _start(_scenario(tmp_path, (200.0, 100.0, 200.0)), out, "--duration", "500")
    _wait_under_way(proc, out, rows=5)
    proc.kill()
    proc.communicate(timeout=60)
    left = {p.name for p in out.iterdir()}
    assert not left & FINAL, left  # the earlier run's files went before this one wrote
    assert left == {LOCK_NAME, "timeseries.csv.partial", "recording.rrd.partial"}
    assert (out / LOCK_NAME).read_text().split()[0] == str(proc.pid)
    fresh = _cli(str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "1", cwd=tmp_path)
    assert fresh.returncode == 0, fresh.stderr
    assert {p.name for p in out.iterdir()} == FINAL
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["ticks_recorded"] == _check_csv(out / "timeseries.csv") == 26


class _FullDisk:
    """A file object whose writes fail as on a full disk (the rest is the real file's)."""

    def __init__(self, f) -> None:
        self._f = f

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __getattr__(self, name: str):
        return getattr(self._f, name)


def test_a_full_disk_is_a_one_line_error_and_no_final_name(tmp_path, monkeypatch, capsys):
    init = TimeseriesWriter.__init__

    def full_disk_init(self, *args, **kwargs) -> None:
        init(self, *args, **kwargs)
        self._file = _FullDisk(self._file)

    monkeypatch.setattr(TimeseriesWriter, "__init__", full_disk_init)
    out = tmp_path / "out"
    code = main(["run", str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "2"])
    err = capsys.readouterr().err
    assert code == 1, err
    line = _one_error_line(err)
    assert str(out / "timeseries.csv.partial") in line and "No space left on device" in line
    assert {p.name for p in out.iterdir()} == {"timeseries.csv.partial", "recording.rrd.partial"}


def test_a_stop_while_the_outputs_open_leaves_nothing(tmp_path, monkeypatch, capsys):
    """Ctrl-C after the CSV was begun, while the Rerun file opens: no header-only partial, no
    lock, the earlier run's outputs gone as the claim said; a user's file is kept."""
    from cdpr_twin.recording import sinks as recorders

    def interrupted(*args, **kwargs):
        assert (out / "timeseries.csv.partial").exists()  # the CSV was begun
        raise KeyboardInterrupt

    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text(EARLIER_SUMMARY % "completed")  # an earlier run's
    (out / "notes.txt").write_text("mine")
    monkeypatch.setattr(recorders, "RerunRecorder", interrupted)
    code = main(["run", str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "1"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 130 and "interrupted before this run saved any output" in line
    assert {p.name for p in out.iterdir()} == {"notes.txt"}


def test_a_stop_while_the_files_open_leaves_no_directory_the_run_created(
    tmp_path, monkeypatch, capsys
):
    """SIGTERM while the Rerun file opens, in an --out that did not exist: before, the empty
    directory and its new parents stayed behind."""
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.recording import sinks as recorders

    def terminated(*args, **kwargs):
        raise Terminated()

    out = tmp_path / "new" / "deeper" / "out"
    monkeypatch.setattr(recorders, "RerunRecorder", terminated)
    code = main(["run", str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "1"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 143 and "terminated before this run saved any output" in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("limit", "duration"),
    [(100_000, "3"), (150_000, "3"), (65_000, "1")],
    ids=["csv_first", "rrd_end", "rrd_writer_dies_mid_flush"],
)
def test_a_file_size_limit_is_a_one_line_error_and_no_final_name(tmp_path, limit, duration):
    """A real failing write (RLIMIT_FSIZE: EFBIG, as a full disk gives ENOSPC), whichever file
    meets it; with 150 kB the recording's end (Rerun's footer, written in its own thread) fails.

    With 65 kB the CSV of 1 s (58 kB) is whole and Rerun's file writer dies at the end: its flush
    then waited forever (4 runs in 4 hung, deaf to SIGTERM). The writer's own error or, where it
    never comes, the file standing still for ``watchdog.STALL_S`` now ends the run.
    """

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    out = tmp_path / "out"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "cdpr_twin",
            "run",
            str(OPEN_LOOP),
            "--out",
            str(out),
            "--no-camera",
            "--duration",
            duration,
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
        preexec_fn=limited,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    assert proc.returncode == 1, proc.stderr
    assert ".partial" in _one_error_line(proc.stderr)
    left = {p.name for p in out.iterdir()}
    assert left == {"timeseries.csv.partial", "recording.rrd.partial"}, left


def test_huge_duration_is_a_one_line_error(tmp_path):
    out = tmp_path / "out"
    args = ("--out", str(out), "--no-camera", "--duration", "1e308")
    proc = _cli(str(OPEN_LOOP), *args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "--duration" in _one_error_line(proc.stderr)
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_out_that_is_a_file_is_a_one_line_error(tmp_path):
    out = tmp_path / "out"
    out.write_text("keep me")
    proc = _cli(str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "1", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert str(out) in _one_error_line(proc.stderr)
    assert len(proc.stderr.strip().splitlines()) == 1
    assert out.read_text() == "keep me"


@pytest.mark.parametrize("cause", [errno.EACCES, errno.EROFS], ids=["not_permitted", "read_only"])
def test_out_not_writable_is_a_one_line_error(tmp_path, monkeypatch, capsys, cause):
    # as root chmod cannot forbid anything: the OS's refusal comes through os.open (the lock)
    real_open = os.open

    def refusing_open(path, flags, *args, **kwargs):
        if Path(path).name == LOCK_NAME:
            raise OSError(cause, os.strerror(cause), str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refusing_open)
    out = tmp_path / "out"
    out.mkdir()
    code = main(["run", str(OPEN_LOOP), "--out", str(out), "--no-camera", "--duration", "1"])
    err = capsys.readouterr().err
    assert code == 2, err
    line = _one_error_line(err)
    assert str(out) in line and os.strerror(cause) in line
    assert list(out.iterdir()) == []


@pytest.mark.parametrize(
    ("cause", "fix"),
    [(errno.ENOSPC, "(free some space, or copy into"), (errno.EROFS, "(copy into another dir")],
)
def test_a_failed_write_advises_what_its_cause_needs(tmp_path, monkeypatch, capsys, cause, fix):
    """Before: "free some space" whatever the cause (a read-only file system too)."""
    real_open = os.open

    def refusing_open(path, *args, **kwargs):
        if str(path).endswith(".partial"):
            raise OSError(cause, os.strerror(cause), str(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", refusing_open)
    assert main(["scenarios", "copy", "paper_pbvs", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cdpr-twin scenarios copy: error: cannot")
    assert os.strerror(cause) in err and fix in err
    assert list(tmp_path.iterdir()) == []


def test_unreadable_scenario_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    scenario = tmp_path / "secret.toml"
    scenario.write_text(OPEN_LOOP.read_text())
    real_open = os.open

    def refusing_open(path, *args, **kwargs):
        if Path(path) == scenario:  # (as root, a chmod 000 file is read all the same)
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", refusing_open)
    code = main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-camera"])
    err = capsys.readouterr().err
    assert code == 2, err
    line = _one_error_line(err)
    assert str(scenario) in line and "Permission denied" in line
    assert not (tmp_path / "out").exists()


def test_lock_of_a_live_owner_is_kept_and_a_dead_owners_is_taken(tmp_path):
    (tmp_path / LOCK_NAME).write_text(f"{os.getppid()} {socket.gethostname()}\n")
    with pytest.raises(OutputDirError, match="in use by another run"):
        OutputDir(tmp_path).claim()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / LOCK_NAME).write_text(f"{dead.pid} {socket.gethostname()}\n")
    owner = OutputDir(tmp_path)
    owner.claim()
    assert (tmp_path / LOCK_NAME).read_text().split()[0] == str(os.getpid())
    owner.release()
    assert not (tmp_path / LOCK_NAME).exists()


@pytest.mark.parametrize(
    ("partials", "ours"),
    [
        (None, "summary.json.partial"),  # a run's
        ("campaign", "effect_seed.png.partial"),  # CAMPAIGN_FILES: what a campaign passes
    ],
)
def test_a_claim_removes_its_owners_partial_files_not_the_users(tmp_path, partials, ours):
    # before: every *.partial in --out went, a user's unfinished "thesis.tex.partial" too
    from cdpr_twin.campaign import CAMPAIGN_FILES
    from cdpr_twin.files.transaction import OutputDir

    partials = CAMPAIGN_FILES if partials == "campaign" else partials

    out = tmp_path / "out"
    out.mkdir()
    for name in (ours, "thesis.tex.partial", "notes.partial"):
        (out / name).write_text("x")
    owner = OutputDir(out, partials=partials) if partials else OutputDir(out)
    owner.claim()
    owner.release()
    assert sorted(p.name for p in out.iterdir()) == ["notes.partial", "thesis.tex.partial"]


LONG = "y" * 300  # a path component over NAME_MAX (255 bytes): the OS says ENAMETOOLONG
ACROBOT = ROOT / "models" / "acrobot" / "robot.toml"


@pytest.mark.parametrize(
    "argv",
    [
        ["run", str(OPEN_LOOP), "--out", "LONG", "--no-camera", "--duration", "0.2"],
        ["run", "LONG.toml"],
        ["run", LONG],  # a bare name: neither a file here nor a shipped scenario
        ["reproduce", "--out", "LONG", "--duration", "0.2", "--runs-scale", "0.01"],
        ["calibrate", str(OPEN_LOOP), "--poses", "12", "--out", "LONG"],
        ["calibrate", str(OPEN_LOOP), "--poses", "12", "--out", "made/LONG"],
        ["calibrate", "LONG.toml"],
        ["model", "workspace", str(ACROBOT), "--out", "LONG/ws.png"],
        ["model", "build", str(ACROBOT), "--out", "LONG"],
        ["scenarios", "copy", "paper_pbvs", "LONG"],
        ["view", "LONG"],
    ],
    ids=[
        "run --out",
        "run FILE",
        "run NAME",
        "reproduce --out",
        "calibrate --out",
        "calibrate --out (parent made)",
        "calibrate FILE",
        "model workspace --out",
        "model build --out",
        "scenarios copy",
        "view",
    ],
)
def test_a_path_the_os_refuses_is_one_line_naming_it_and_nothing_is_left(
    argv, tmp_path, monkeypatch, capsys
):
    """Python 3.11's ``Path.exists()`` raised it: a traceback (or "the run failed", exit 1)."""
    monkeypatch.chdir(tmp_path)
    code = main([a.replace("LONG", LONG) for a in argv])
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert LONG in err and "File name too long" in err
    assert list(tmp_path.iterdir()) == []  # not even the parent directory made for it


def test_a_scenario_name_too_long_for_its_directory_leaves_nothing_then_again(
    tmp_path, monkeypatch, capsys
):
    """``runs/<name>`` could not be made: the first run left ``runs/``, the second failed (exit
    1). The name is refused as the file's field now, before any directory is touched."""
    text = _scenario(tmp_path, (10.0, 5.0, 10.0)).read_text()
    scenario = tmp_path / "long.toml"
    scenario.write_text(text.replace('name = "paper_open_loop"', f'name = "{LONG}"', 1))
    monkeypatch.chdir(tmp_path)
    for kept in ([], ["runs"]):  # no runs/ (the claim makes it, then removes it); the user's
        for name in kept:
            (tmp_path / name).mkdir()
        assert main(["run", str(scenario), "--no-camera", "--duration", "0.2"]) == 2
        line = _one_error_line(capsys.readouterr().err)
        assert f"{scenario}: name: must be at most 255 bytes" in line and LONG[:50] in line
        left = sorted(p.name for p in tmp_path.iterdir())
        assert left == sorted(["long.toml", "slow_25.toml", *kept])
    assert list((tmp_path / "runs").iterdir()) == []


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
