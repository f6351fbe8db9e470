"""A campaign's workers stop with it: a SIGTERM ends the runs under way (local processes or
Ray) and says what was kept, a killed campaign leaves no worker simulating, and a Ray address
nothing answers is refused before anything is written."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import group_alive, outlived_by_its_group, pool_threads

ROOT = Path(__file__).resolve().parents[2]


def _campaign(tmp_path: Path, name: str, duration: float, camera: bool, seeds=(1,)) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        f'[overrides]\n"sensors.camera" = {str(camera).lower()}\nduration = {duration}\n\n'
        f'[[axes]]\nkey = "seed"\nvalues = {list(seeds)}\n'
    )
    return path


def _start_slow_campaign(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    """Two 30 s camera-on runs on one worker (each many seconds of wall time)."""
    src = _campaign(tmp_path, "slow", 30.0, camera=True, seeds=(1, 2))
    src.write_text(f'artefacts = "all"\n{src.read_text()}')  # the runs under way write files
    out = tmp_path / "slow_out"
    cmd = [
        sys.executable,
        "-m",
        "cdpr_twin",
        "campaign",
        str(src),
        "--out",
        str(out),
        "--workers",
        "1",
    ]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while not any(out.glob("runs/*/.lock")) and time.monotonic() < deadline:
        time.sleep(0.1)  # the worker spawned, imported the package and started its first run
    assert proc.poll() is None, proc.stderr.read()
    assert any(out.glob("runs/*/.lock")), "no run started within 120 s"
    return proc, out


@pytest.mark.slow
def test_sigterm_ends_the_runs_under_way_and_says_nothing_was_recorded(tmp_path):
    proc, out = _start_slow_campaign(tmp_path)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=60)
        waited = time.monotonic() - t0
    finally:
        if group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)  # (the test fails below)
    assert proc.returncode == 143, err
    # before: the worker finished both queued runs (≈ 2 × 20 s), and neither was recorded
    assert waited < 12.0, f"the campaign took {waited:.1f} s to stop"
    assert "terminated; no run finished now" in err
    assert "Traceback" not in err
    assert json.loads((out / "campaign.json").read_text())["status"] == "terminated"
    assert not (out / "results.parquet").exists()
    time.sleep(0.5)
    assert not group_alive(proc.pid), "a worker process outlived the campaign"
    assert not _leftovers(out)  # before: the run under way kept its .lock and *.partial files


def _leftovers(out: Path) -> list[str]:
    """The locks and ``*.partial`` files under a directory's ``runs/``."""
    found = (out / "runs").rglob("*")
    return [str(p.relative_to(out)) for p in found if p.name == ".lock" or p.suffix == ".partial"]


@pytest.mark.slow
def test_a_killed_campaign_leaves_no_worker_simulating(tmp_path):
    proc, _ = _start_slow_campaign(tmp_path)
    alive = outlived_by_its_group(proc)  # the parent alone, without any cleanup
    assert not alive, "the spawned worker kept running after its campaign was killed"


def test_a_stopped_local_executor_ends_its_workers_without_a_thread_traceback(monkeypatch):
    # truth: Python's own report of an exception escaping a thread (threading.excepthook).
    # Before: a stop while the workers were still starting cancelled the queued future here,
    # and the pool's thread, failing the futures of its ended workers, raised InvalidStateError
    import multiprocessing
    import threading

    from cdpr_twin.campaign.executor import run_local

    escaped = []
    monkeypatch.setattr(threading, "excepthook", escaped.append)
    for when in (0.2, 3.0):  # Ctrl-C while the workers start, and while they run
        results = run_local(time.sleep, [5.0] * 8, 2)  # fn(item): each run takes 5 s
        threading.Timer(when, os.kill, (os.getpid(), signal.SIGINT)).start()
        with pytest.raises(KeyboardInterrupt):
            next(results)
        # the workers were ended, not left to finish their 5 s runs (truth: the OS's processes)
        assert multiprocessing.active_children() == []
        assert pool_threads() == []  # none left to race Python's exit hook on its pipe
        assert escaped == []


def test_a_ray_address_nothing_answers_is_a_one_line_error_before_anything_is_written(tmp_path):
    # before: Ray retried the connection for minutes, after the directory had been made
    import socket

    with socket.socket() as probe:  # a port that was free a moment ago: nothing listens there
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    src = _campaign(tmp_path, "c", 1.0, camera=False, seeds=(1,))
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "cdpr_twin",
        "campaign",
        str(src),
        "--out",
        str(out),
        "--ray",
        f"127.0.0.1:{port}",
    ]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert time.monotonic() - t0 < 60.0
    assert proc.stderr.count("\n") == 1 and f"cannot start Ray on 127.0.0.1:{port}" in proc.stderr
    assert not out.exists()


def _ray_head_started(pgid: int) -> bool:
    """Whether the campaign of process group ``pgid`` has Ray's head up: it is in ``ray.init``
    (Ray's GCS server starts first; the driver connects seconds later), or past it."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            comm, fields = stat.read_text().rsplit(")", 1)
        except OSError:
            continue
        if comm.endswith("(gcs_server") and int(fields.split()[2]) == pgid:
            return True
    return False


def _sigterm_a_ray_campaign(tmp_path: Path, ready) -> tuple[subprocess.Popen, str, Path]:
    """Start a two-run Ray campaign, wait for ``ready(out, pid)``, SIGTERM it; (process, stderr,
    out)."""
    src = _campaign(tmp_path, "slow", 30.0, camera=True, seeds=(1, 2))
    src.write_text(f'artefacts = "csv"\n{src.read_text()}')  # a run's directory marks its start
    out = tmp_path / "ray_out"
    cmd = [sys.executable, "-m", "cdpr_twin", "campaign", str(src), "--out", str(out), "--ray"]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 240
        while not ready(out, proc.pid) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert proc.poll() is None and ready(out, proc.pid), "the campaign never got that far"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
        deadline = time.monotonic() + 30
        while group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = group_alive(proc.pid)  # Ray's head and actors are in the campaign's group
    finally:
        if group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not left, "a Ray process outlived the stopped campaign"
    return proc, err, out


@pytest.mark.slow
def test_sigterm_while_ray_starts_stops_the_campaign_as_terminated(tmp_path):
    # before: Ray's handler, installed for the length of ray.init (seconds on a loaded machine),
    # exited `error: sys.exit(15) called`, status failed, and the half-started driver aborted
    pytest.importorskip("ray", reason="Ray has no wheel for this platform")
    proc, err, out = _sigterm_a_ray_campaign(tmp_path, lambda out, pid: _ray_head_started(pid))
    assert proc.returncode == 143, err
    assert "cdpr-twin: terminated;" in err and "Traceback" not in err
    assert json.loads((out / "campaign.json").read_text())["status"] == "terminated"


@pytest.mark.slow
def test_sigterm_stops_a_ray_campaign_with_runs_under_way_as_terminated(tmp_path):
    # before: Ray's own SIGTERM handler made it `error: sys.exit(1) called`, exit 1, status
    # failed; then Ray's signal check re-raised the Terminated as a plain Ctrl-C (exit 130)
    pytest.importorskip("ray", reason="Ray has no wheel for this platform")
    proc, err, out = _sigterm_a_ray_campaign(
        tmp_path, lambda out, pid: (out / "runs").is_dir() and any((out / "runs").iterdir())
    )
    assert proc.returncode == 143, err
    assert "cdpr-twin: terminated;" in err and "Traceback" not in err
    assert json.loads((out / "campaign.json").read_text())["status"] == "terminated"
    assert not _leftovers(out)
