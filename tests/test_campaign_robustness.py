"""A campaign's directory is its own: a run's directory is not taken (nor a campaign's by a run),
a resume never mixes two campaigns into one table, a stop ends the runs under way and says what
was kept, a killed campaign leaves no worker simulating, and an empty ``--out`` is refused.
Also: a broken estimator's NaN pose is counted, not measured."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import group_alive, outlived_by_its_group, pool_threads

from cdpr_twin.campaign import load_campaign, load_table, run_campaign
from cdpr_twin.cli import main
from cdpr_twin.files.transaction import OutputDirError
from cdpr_twin.run.metrics import NON_FINITE_ESTIMATE, DeviationTrack
from cdpr_twin.types import PoseEstimate

ROOT = Path(__file__).resolve().parent.parent


def _campaign(tmp_path: Path, name: str, duration: float, camera: bool, seeds=(1,)) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        f'[overrides]\n"sensors.camera" = {str(camera).lower()}\nduration = {duration}\n\n'
        f'[[axes]]\nkey = "seed"\nvalues = {list(seeds)}\n'
    )
    return path


def _run_files(directory: Path) -> dict[str, bytes]:
    directory.mkdir(parents=True, exist_ok=True)
    files = {"summary.json": b'{"status": "completed"}\n', "timeseries.csv": b"time\n0\n"}
    for name, content in files.items():
        (directory / name).write_bytes(content)
    return files


def test_a_campaign_refuses_a_runs_directory_and_leaves_the_run_intact(tmp_path, capsys):
    files = _run_files(tmp_path / "a_run")
    src = _campaign(tmp_path, "tiny", 0.2, camera=False)
    for extra in ([], ["--resume"]):
        assert main(["campaign", str(src), "--out", str(tmp_path / "a_run"), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert "holds another command's outputs" in err and "\n" not in err
    assert {p.name: p.read_bytes() for p in (tmp_path / "a_run").iterdir()} == files


def test_a_run_refuses_a_campaigns_directory(tmp_path, capsys):
    out = tmp_path / "a_campaign"
    out.mkdir()
    (out / "campaign.json").write_text('{"campaign": "x"}\n')
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "0.08", "--no-camera"]
    assert main(argv) == 2
    assert "holds another command's outputs (campaign.json)" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["campaign.json"]


def test_resuming_with_another_campaign_is_refused_and_the_table_kept(tmp_path):
    first = load_campaign(_campaign(tmp_path, "first", 0.2, camera=False))
    out = tmp_path / "out"
    assert run_campaign(first, out, workers=1)["ran_now"] == 1
    table = load_table(out).to_pylist()
    other = load_campaign(_campaign(tmp_path, "other", 0.12, camera=False, seeds=(1, 2)))
    assert {t.run_id for t in other.tasks}.isdisjoint(t.run_id for t in first.tasks)
    with pytest.raises(OutputDirError, match=r"does not have .* mix them into one table"):
        run_campaign(other, out, workers=1, resume=True)
    assert load_table(out).to_pylist() == table
    # the same campaign with one more run resumes: the old rows are its own
    grown = load_campaign(_campaign(tmp_path, "first", 0.2, camera=False, seeds=(1, 2)))
    assert run_campaign(grown, out, workers=1, resume=True)["ran_now"] == 1
    assert len(pq.read_table(out / "results.parquet")) == 2


def test_an_empty_out_is_refused_not_taken_for_the_current_directory(tmp_path, capsys, monkeypatch):
    src = _campaign(tmp_path, "tiny", 0.2, camera=False)
    monkeypatch.chdir(tmp_path)  # were it taken, the campaign would write here
    with pytest.raises(SystemExit) as exit_:
        main(["campaign", str(src), "--out", ""])
    assert exit_.value.code == 2 and "--out: is empty" in capsys.readouterr().err


def _start_slow_campaign(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    """Two 30 s camera-on runs on one worker (each many seconds of wall time)."""
    src = _campaign(tmp_path, "slow", 30.0, camera=True, seeds=(1, 2))
    src.write_text(f'artefacts = "all"\n{src.read_text()}')  # the runs under way write files
    out = tmp_path / "slow_out"
    cmd = [sys.executable, "-m", "cdpr_twin", "campaign", str(src), "--out", str(out),
           "--workers", "1"]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
        start_new_session=True,
    )  # fmt: skip
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


def test_a_nan_estimate_is_counted_invalid_not_dropped_from_the_deviations():
    track = DeviationTrack()
    T = np.eye(4)
    track.add(PoseEstimate(0.04, T), (0.001, 0.002))
    track.add(PoseEstimate(0.08, np.full((4, 4), np.nan)), (math.nan, math.nan))
    track.add(PoseEstimate(0.12, T), (0.003, 0.001))
    s = track.summary()
    assert s["invalid_updates"] == 1 and s["flags"] == {NON_FINITE_ESTIMATE: 1}
    assert s["max_translation_m"] == 0.003 and s["max_translation_time_s"] == 0.12
    assert s["rms_translation_m"] == pytest.approx(math.sqrt((0.001**2 + 0.003**2) / 2))
    track.add(PoseEstimate(0.16, np.full((4, 4), np.nan)), (math.nan, math.nan))
    assert math.isnan(track.summary()["final_translation_m"])  # the last estimate: none


NAN_ESTIMATOR = """
import numpy as np
from cdpr_twin import plugins
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.types import PoseEstimate


@plugins.register
class Broken(Estimator):
    name = "broken"

    def update(self, measurement, inputs=NO_INPUTS):
        self._check_reset()
        return PoseEstimate(measurement.time, np.full((4, 4), np.nan))
"""


def test_an_estimator_that_never_estimates_has_no_deviation_and_wins_nothing(tmp_path):
    # before: max and RMS deviations of 0 over no estimate at all, and in a campaign's report
    # the broken estimator "deviated least" in every run
    (tmp_path / "broken.py").write_text(NAN_ESTIMATOR)
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('name = "paper_open_loop"', 'name = "broken"\nplugins = ["broken.py"]')
    text = text.replace('passive = ["image", ', 'passive = ["broken", "image", ')
    (tmp_path / "broken.toml").write_text(text)
    src = tmp_path / "c.toml"
    src.write_text(
        f'name = "c"\nscenario = "{tmp_path / "broken.toml"}"\n\n[overrides]\n'
        '"sensors.camera" = false\nduration = 0.2\n\n[[axes]]\nkey = "seed"\nvalues = [1, 2]\n'
    )
    out = tmp_path / "out"
    assert main(["campaign", str(src), "--out", str(out)]) == 0
    rows = load_table(out).to_pylist()
    for row in rows:
        broken = json.loads(row["summary"])["estimators"]["broken"]
        assert broken["invalid_updates"] == 6  # the start and five ticks, none finite
        assert broken["max_translation_m"] is None and broken["rms_translation_m"] is None
        assert math.isnan(row["est.broken.rms_t_m"]) and row["est.model_simple.rms_t_m"] > 0
    report = (out / "report.md").read_text()
    assert "| model_simple |" in report and "| broken |" not in report


def test_a_waypoint_outside_the_frame_through_an_axis_is_refused_before_any_run(tmp_path):
    from cdpr_twin.campaign import CampaignError

    p1, p0 = [0.284, -0.197, 0.08, 0, 0, 0], [0.1, 0.0, 0.3, 0, 0, 0]
    good, bad = [p1, [0.284, -0.197, 0.25, 0, 0, 0], p0], [p1, [0.284, -0.197, 2.5, 0, 0, 0], p0]
    path = tmp_path / "axis.toml"
    path.write_text(
        f'name = "axis"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        f'[[axes]]\nkey = "controller.waypoints"\nvalues = [{good}, {bad}]\n'
    )
    with pytest.raises(CampaignError, match=r"waypoints\[1\].* is outside the frame"):
        load_campaign(path)  # was: a failed row, after the runs before it had run


BASE = f'scenario = "{ROOT}/scenarios/paper_open_loop.toml"\n'


@pytest.mark.parametrize(
    ("text", "where"),
    [  # each was a traceback (KeyError, ValueError, OverflowError) while drawing
        ('[[axes]]\nkey = "seed"\ndraw = "choice"\n', r"axes\[0\]\.values: .*needs values"),
        ('[[axes]]\nkey = "seed"\ndraw = "normal"\nmean = 1\nstd = -1\n', r"std: must be > 0"),
        (
            '[[axes]]\nkey = "seed"\ndraw = "integers"\nlow = 1\nhigh = 1e20\n',
            r"high \(seed\): .*64-bit",
        ),
        (
            '[[axes]]\nkey = "seed"\ndraw = "integers"\nlow = 0.5\nhigh = 9\n',
            r"low \(seed\): .*64-bit",
        ),
        (
            '[[axes]]\nkey = "truth.exit_point_std"\n'
            'draw = "uniform"\nlow = -1e308\nhigh = 1e308\n',
            r"high: high − low must be a finite",
        ),
    ],
)
def test_a_random_axis_that_cannot_be_drawn_is_a_one_line_error(tmp_path, text, where):
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text('name = "c"\n' + BASE + text)
    with pytest.raises(CampaignError, match=where):
        load_campaign(path)


@pytest.mark.parametrize("key", ["samples = 3", "smaples = 3", 'artefacts = "bogus"', BASE.strip()])
def test_top_level_run_keys_beside_blocks_are_refused_not_ignored(tmp_path, key):
    """They were ignored: a typo'd ``samples`` ran one run where three were meant."""
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text(f'name = "c"\n{key}\n\n[[blocks]]\nname = "b"\n{BASE}')
    with pytest.raises(CampaignError, match="not allowed beside"):
        load_campaign(path)


@pytest.mark.parametrize("name", ["..", ".", "a\\\\b"])
def test_a_campaign_name_that_is_not_a_plain_directory_name_is_refused(tmp_path, name):
    """``..`` was accepted: the default output runs/.. is the current directory."""
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text(f'name = "{name}"\n' + BASE)
    with pytest.raises(CampaignError, match="plain name"):
        load_campaign(path)


def test_a_resume_that_cannot_write_its_table_leaves_no_stale_table(tmp_path, monkeypatch):
    """A full disk at the end of a resume left results.parquet (and campaign.json) describing
    the runs before it under their final names; now they go when new runs start, and the next
    --resume writes them from the parts."""
    from cdpr_twin.campaign import table as table_mod
    from cdpr_twin.files.transaction import OutputError

    out = tmp_path / "out"
    two = load_campaign(_campaign(tmp_path, "grow", 0.2, camera=False, seeds=(1, 2)))
    assert run_campaign(two, out, workers=1)["ran_now"] == 2
    (out / "report.md").write_text("the report of 2 runs\n")
    three = load_campaign(_campaign(tmp_path, "grow", 0.2, camera=False, seeds=(1, 2, 3)))

    def disk_full(self, order=()):
        raise OutputError(out / "results.parquet.partial", "No space left on device")

    with monkeypatch.context() as m:
        m.setattr(table_mod.ResultTable, "gather", disk_full)
        with pytest.raises(OutputError):
            run_campaign(three, out, workers=1, resume=True)
    assert not (out / "results.parquet").exists() and not (out / "report.md").exists()
    assert json.loads((out / "campaign.json").read_text())["status"] == "running"
    again = run_campaign(three, out, workers=1, resume=True)
    assert again["ran_now"] == 0 and again["status"] == "completed"
    assert sorted(load_table(out).column("seed").to_pylist()) == [1, 2, 3]


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
    cmd = [sys.executable, "-m", "cdpr_twin", "campaign", str(src), "--out", str(out),
           "--ray", f"127.0.0.1:{port}"]  # fmt: skip
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
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
        start_new_session=True,
    )  # fmt: skip
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
