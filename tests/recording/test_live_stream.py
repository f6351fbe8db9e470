"""`cdpr-twin run --connect ADDR` streams a running scenario live to a Rerun gRPC server.

The test starts a headless Rerun server (the rerun-sdk's own CLI: ``rerun --port P --save
FILE`` listens for SDK connections and streams what it receives to FILE), runs the open-loop
scenario connected to it, stops the server, and reads the entity paths the *server* received
with ``rerun rrd stats``.
"""

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cdpr_twin.cli.tools import live_url
from cdpr_twin.recording import rerun as record

RERUN = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, server: subprocess.Popen, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert server.poll() is None, server.stderr.read()
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise AssertionError(f"the Rerun server did not listen on {port} within {timeout} s")


def _wait_stable(path: Path, timeout: float = 15.0) -> None:
    """Until the server's file has stopped growing for half a second (it saved what it got)."""
    deadline, last, since = time.monotonic() + timeout, -1, time.monotonic()
    while time.monotonic() < deadline:
        size = path.stat().st_size if path.exists() else -1
        if size != last:
            last, since = size, time.monotonic()
        elif size > 0 and time.monotonic() - since > 0.5:
            return
        time.sleep(0.1)


def _entities(rrd: Path, env: dict) -> set[str]:
    """The scenario's entity paths in a recording (blueprint entities left out)."""
    stats = subprocess.run(
        [RERUN, "rrd", "stats", str(rrd)], capture_output=True, text=True, env=env, timeout=60
    )
    assert stats.returncode == 0, stats.stderr
    paths = {line.split(":")[0] for line in stats.stdout.splitlines() if line.startswith("/")}
    return {p for p in paths if p.split("/")[1] in ("world", "deviation", "tension", "length")}


def test_a_run_streams_its_entities_to_a_rerun_grpc_server(tmp_path):
    assert RERUN is not None, "the rerun CLI (installed by rerun-sdk) is not on this machine"
    env = {**os.environ, "RERUN_ANALYTICS": "0", "MUJOCO_GL": "egl"}
    port, received = _free_port(), tmp_path / "server.rrd"
    server = subprocess.Popen(
        [RERUN, "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,  # its own process group: the wrapper script and the binary
    )
    try:
        _wait_listening(port, server)
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "cdpr_twin",
                "run",
                "paper_open_loop",
                "--duration",
                "1",
                "--no-camera",
                "--out",
                str(tmp_path / "out"),
                "--connect",
                str(port),
            ],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp_path,
            timeout=300,
        )
        assert proc.returncode == 0, proc.stderr
        _wait_stable(received)
    finally:
        os.killpg(server.pid, signal.SIGINT)  # Ctrl-C: the server finishes its file and exits
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
    assert received.is_file() and received.stat().st_size > 0
    on_server = _entities(received, env)
    expected = {
        "/world/frame",
        "/world/exit_points",
        "/world/tag",
        "/world/cables",
        "/world/platform",
        "/world/plan",
        "/deviation/translation_mm",
        "/deviation/rotation_deg",
        "/tension",
        "/length",
        "/world/estimates/control",
        "/world/estimates/model_elastic_pulley",
    }
    assert expected <= on_server, sorted(expected - on_server)
    # the same entities as the run's own file (the camera is off: no image)
    assert _entities(tmp_path / "out" / "recording.rrd", env) == on_server
    assert "/world/platform/cam/image" not in on_server


def test_a_server_that_does_not_listen_delays_the_end_of_a_run_only_briefly(tmp_path):
    """Nothing at the address: the run ends (it used to wait forever in Rerun's flush, its
    signals held), warns, and its own recording is whole, with every entity. 2 s of run: with
    less, Rerun's client buffers it all and never blocks."""
    env = {**os.environ, "RERUN_ANALYTICS": "0", "MUJOCO_GL": "egl"}
    start = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "cdpr_twin",
            "run",
            "paper_open_loop",
            "--duration",
            "2",
            "--no-camera",
            "--out",
            str(tmp_path / "out"),
            "--connect",
            str(_free_port()),
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "live viewer did not take all of the recording" in proc.stderr
    # the run, the flush's limit, Rerun's own 5 s for a last connection attempt
    assert time.monotonic() - start < 60.0 + record.LIVE_FLUSH_TIMEOUT_S
    assert {"/world/platform", "/tension", "/world/estimates/fused"} <= _entities(
        tmp_path / "out" / "recording.rrd", env
    )


@pytest.mark.parametrize(
    "address", ["0", "99999", "host:70000", "rerun+http://host:0/proxy", "rerun://host:70000/proxy"]
)
def test_a_port_out_of_range_is_refused(address):
    with pytest.raises(ValueError, match="not a TCP port"):
        live_url(address)
