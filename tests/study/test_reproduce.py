"""`cdpr-twin reproduce`, scaled down, end to end: artefacts exist and every report number is
recomputed from the runs' own files.

On bad input (a full disk, a second writer, SIGTERM, an impossible duration, a plugin that
raises; and `run` with such a plugin) each gets one line and a documented exit code; no final
name is left truncated or stale. The full-disk tests do not run the study: ``run_local`` is
replaced by a copy of a tiny study's runs (made once, really), so only the study's own writes
(``runs.json``, ``report.json``, the figures, ``report.md``) meet the "disk".
"""

import builtins
import csv
import errno
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import EARLIER_SUMMARY

from cdpr_twin import plugins
from cdpr_twin.cli import main
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.files.transaction import OutputDir, partial_of
from cdpr_twin.study import reproduce
from cdpr_twin.study.results import PAPER_ESTIMATORS
from cdpr_twin.types import PoseEstimate

ROOT = Path(__file__).resolve().parents[2]
TINY = ("--duration", "0.2", "--runs-scale", "0.01", "--workers", "1")
STUDY_FILES = ("runs.json", "report.json", "fig5a.png", "fig7b.png", "report.md")
P1 = np.array([0.284, -0.197, 0.08])


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    rep = reproduce(out, workers=2, runs_scale=0.1, duration=11.0)
    return out, rep


def _rows(run_dir: Path) -> list[dict]:
    with (run_dir / "timeseries.csv").open() as f:
        return list(csv.DictReader(f))


def _xyz(row: dict, prefix: str) -> np.ndarray:
    return np.array([float(row[f"{prefix}_{k}"]) for k in "xyz"])


@pytest.mark.slow
def test_reproduce_writes_every_artefact(small):
    import cv2

    out, rep = small
    records = json.loads((out / "runs.json").read_text())
    assert len(records) == 1 + 7 and all(r["ok"] for r in records)  # PBVS: the six and fused
    assert rep["runs"] == {"total": 8, "ok": 8, "failed": []}
    for name in ("fig5a", "fig5b", "fig7a", "fig7b", "fig8"):
        img = cv2.imread(str(out / f"{name}.png"))
        assert img is not None and img.shape == (600, 1200, 3), name
        assert img.std() > 10, f"{name} looks blank"
    report = (out / "report.md").read_text()
    assert all(f"({n}.png)" in report for n in ("fig5a", "fig5b", "fig7a", "fig7b", "fig8"))
    assert (out / "runs" / "open_loop_seed1" / "recording.rrd").exists()
    assert not list(out.glob("*.partial")) and not (out / ".lock").exists()  # whole, released


@pytest.mark.slow
def test_report_numbers_are_recomputed_from_the_run_files(small):
    out, _ = small
    rep = json.loads((out / "report.json").read_text())
    report_md = (out / "report.md").read_text()
    # open loop: each estimator's max translational deviation, and the miss at p1 (t = 10 s)
    rows = _rows(out / "runs" / "open_loop_seed1")
    for name, e in rep["open_loop"]["estimators"].items():
        dev = [np.linalg.norm(_xyz(r, name) - _xyz(r, "true")) for r in rows]
        assert e["max_translation_m"] == pytest.approx(max(dev), abs=1e-12)
    at10 = min(rows, key=lambda r: abs(float(r["t"]) - 10.0))
    miss = np.linalg.norm(_xyz(at10, "true") - _xyz(at10, "plan"))
    assert rep["open_loop"]["miss_at_p1"]["translation_m"] == pytest.approx(miss, abs=1e-12)
    assert f"{miss * 100:.2f} cm" in report_md
    # accuracy at p1: open loop at t = 10 s, PBVS at the end of each run
    expected = {"open loop": [np.linalg.norm(_xyz(at10, "true") - P1)]}
    for name in (*PAPER_ESTIMATORS, "fused"):  # the PBVS file's estimators, each in the loop
        run_dir = out / "runs" / f"pbvs_{name}_seed1"
        summary = json.loads((run_dir / "summary.json").read_text())
        if summary["status"] != "converged":
            continue
        err = np.linalg.norm(_xyz(_rows(run_dir)[-1], "true") - P1)
        expected.setdefault("PBVS (all)", []).append(err)
        expected[f"PBVS {name}"] = [err]
        assert rep["pbvs"][name]["status"] == "converged"
    for key, values in expected.items():
        np.testing.assert_allclose(rep["accuracy"][key]["translation_m"], values, atol=1e-12)
    if "ratios" in rep:
        ratio = np.mean(expected["open loop"]) / np.mean(expected["PBVS (all)"])
        assert rep["ratios"]["translation_m"] == pytest.approx(ratio, rel=1e-12)
        assert f"{ratio:.1f}×" in report_md
    # every finding's verdict is in the report as computed
    for f in rep["findings"]:
        assert f"| {f['finding']} |" in report_md and f"**{f['verdict']}**" in report_md


@pytest.mark.slow
def test_notebook_runs_as_its_text_says(small, tmp_path):
    """As a user follows the text: the study's output in ``runs/reproduce`` beside
    ``notebooks/``, the notebook run from its own directory with no variable set. The output
    is a copy elsewhere, so a run directory recorded as an absolute path (or relative to where
    ``reproduce`` ran) would not be found."""
    import nbformat
    from nbclient import NotebookClient

    out, _ = small
    checkout = tmp_path / "checkout"
    shutil.copytree(out, checkout / "runs" / "reproduce")
    (checkout / "notebooks").mkdir()
    nb = nbformat.read(ROOT / "notebooks" / "paper_figures.ipynb", as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")  # committed bare
    assert "cdpr-twin reproduce --out runs/reproduce" in nb.cells[0].source
    records = json.loads((checkout / "runs" / "reproduce" / "runs.json").read_text())
    assert all(not Path(r["dir"]).is_absolute() for r in records)
    env_before = os.environ.pop("CDPR_TWIN_RESULTS", None)
    try:
        NotebookClient(
            nb,
            timeout=600,
            kernel_name="python3",
            resources={"metadata": {"path": str(checkout / "notebooks")}},
        ).execute()
    finally:
        if env_before is not None:
            os.environ["CDPR_TWIN_RESULTS"] = env_before
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o["output_type"] == "error"], outputs
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 5


def test_the_plan_follows_the_pbvs_scenario_estimators(tmp_path):
    from cdpr_twin.study import plan

    text = (ROOT / "scenarios" / "paper_pbvs.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = text.replace('passive = ["image", "model_simple", ', "passive = [")
    pbvs = tmp_path / "pbvs.toml"
    pbvs.write_text(text)
    specs = plan(0.4, pbvs=pbvs)
    assert [s.name for s in specs if s.kind == "open_loop"] == [
        "open_loop_seed1",
        "open_loop_seed2",
        "open_loop_seed3",
        "open_loop_seed4",
    ]
    in_loop = [s.in_loop for s in specs if s.kind == "pbvs"]
    assert in_loop == [
        n
        for n in (*PAPER_ESTIMATORS, "fused")
        if n not in ("image", "model_simple")
        for _ in range(2)
    ]
    assert all(s.record_rrd == (s.seed == 1) for s in specs)


def test_findings_and_report_take_any_estimator(tmp_path):
    from cdpr_twin.study import evaluate, write_report
    from cdpr_twin.study.criteria import NEEDS_POPULATION

    run = {"status": "converged", "max_translation_m": 0.002, "max_rotation_deg": 0.1}
    rep = {
        "runs": {"total": 2, "ok": 2, "failed": []},
        "pbvs": {"control": {**run, "max_translation_m": 0.003}, "fused": run},
    }
    rep["findings"] = evaluate(rep)
    (best,) = rep["findings"]
    # one robot judges nothing; the criteria's per-robot condition (control's max deviation at
    # most the best passive paper estimate's: 3 mm vs none here) has no value to hold
    assert best["verdict"] == NEEDS_POPULATION and "fused 2.0 mm" in best["twin"]
    assert "criteria.toml `control_best_pbvs`" in best["criterion"]
    assert set(best) == {"finding", "paper", "twin", "criterion", "verdict", "why"}
    report = write_report(tmp_path, rep, [], 1.0).read_text()
    assert "| PBVS, fused in the loop: max deviation | — | 0.20 cm / 0.10° |" in report


"""The smallest study: one open-loop run and one PBVS run per estimator, 0.2 s each."""


@plugins.register
class FailingMidwayEstimator(Estimator):
    """The start pose, until it raises a RuntimeError at t > 0.2 s (a plugin's bug)."""

    name = "failing_midway"

    def update(self, measurement, inputs=NO_INPUTS):
        if measurement.time > 0.2:
            raise RuntimeError("failing_midway: boom")
        self._check_reset()
        return PoseEstimate(measurement.time, self._T)


@pytest.fixture(scope="module")
def done_study(tmp_path_factory) -> Path:
    """A tiny study, really run (8 runs of 0.2 s): its runs are copied by the fake executor."""
    out = tmp_path_factory.mktemp("study")
    assert main(["reproduce", "--out", str(out), *TINY]) == 0
    return out


def _fake_executor(monkeypatch, study: Path) -> None:
    """``run_local`` yields the done study's records, each run copied into the new runs/."""

    def run_local(fn, specs, workers, runs_dir):
        records = {r["name"]: r for r in json.loads((study / "runs.json").read_text())}
        for spec in specs:
            shutil.copytree(study / "runs" / spec.name, Path(runs_dir) / spec.name)
            yield {**records[spec.name], "dir": str(Path(runs_dir) / spec.name)}

    monkeypatch.setattr("cdpr_twin.campaign.executor.run_local", run_local)


class _FullDisk:
    """A file that takes ``room`` bytes, then fails as a full disk does (ENOSPC)."""

    def __init__(self, f, room: int) -> None:
        self._f, self._room = f, room

    def write(self, data):
        if len(data) > self._room:
            self._f.write(data[: self._room])
            self._f.flush()
            self._room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._room -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


def _disk_fills_at(monkeypatch, out: Path, target: str, room: int = 1000) -> None:
    """Writing a file named ``target*`` in ``out`` fails after ``room`` bytes (ENOSPC)."""
    real_open = builtins.open

    def fake_open(file, mode="r", *args, **kwargs):
        f = real_open(file, mode, *args, **kwargs)
        path = Path(os.fsdecode(file)) if isinstance(file, str | bytes | os.PathLike) else None
        if isinstance(file, int):  # a descriptor the writer made (os.fdopen): its file's name
            path = Path(os.readlink(f"/proc/self/fd/{file}"))
        writes = any(c in mode for c in "wax+")
        if writes and path is not None and path.parent == out and path.name.startswith(target):
            return _FullDisk(f, room)
        return f

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(io, "open", fake_open)


def _one_line(err: str) -> str:
    """The command's only message line (progress lines aside); no traceback."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("cdpr-twin")]
    assert len(lines) == 1, err
    return lines[0]


def _whole(path: Path) -> bool:
    """A study file is complete: JSON parses, a PNG ends with its IEND chunk, text ends a line."""
    data = path.read_bytes()
    if path.suffix == ".json":
        json.loads(data)
        return True
    if path.suffix == ".png":
        return data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")
    return data.endswith(b"\n")


def _snapshot(out: Path) -> dict:
    return {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()}


@pytest.mark.parametrize("target", STUDY_FILES)
def test_a_full_disk_is_one_line_and_leaves_no_truncated_final_file(
    target, done_study, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "study"
    _fake_executor(monkeypatch, done_study)
    _disk_fills_at(monkeypatch, out, target)
    assert main(["reproduce", "--out", str(out), *TINY]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "No space left on device" in line and f"{target}.partial" in line, line
    assert not (out / target).exists() and partial_of(out / target).exists()
    assert not (out / "report.md").exists()  # the last file: never without the others
    finals = [out / n for n in ("runs.json", "report.json", "report.md")] + list(out.glob("*.png"))
    assert all(_whole(p) for p in finals if p.exists())
    assert not (out / ".lock").exists()


def test_the_study_files_are_written_whole_with_their_formats(done_study):
    assert not list(done_study.glob("*.partial")) and not (done_study / ".lock").exists()
    for name in ("runs.json", "report.json", "report.md", "fig5a.png", "fig5b.png", "fig7a.png"):
        assert _whole(done_study / name), name


def test_a_second_writer_is_refused_and_touches_nothing(done_study, tmp_path, capsys):
    out = tmp_path / "study"
    shutil.copytree(done_study, out)
    before = _snapshot(out)
    holder = OutputDir(out)
    holder.claim()  # another study (or run) owns the directory
    try:
        assert main(["reproduce", "--out", str(out), *TINY]) == 2
    finally:
        holder.release()
    assert "in use by another run" in _one_line(capsys.readouterr().err)
    assert _snapshot(out) == before


@pytest.mark.parametrize(
    "option",
    [
        ("--duration", "0"),
        ("--duration", "nan"),
        ("--duration", "-1"),
        ("--runs-scale", "nan"),
        ("--workers", "0"),
    ],
    ids=lambda o: " ".join(o),
)
def test_bad_options_are_refused_before_anything_runs(option, done_study, tmp_path, capsys):
    out = tmp_path / "study"
    shutil.copytree(done_study, out)
    before = _snapshot(out)
    args = dict(zip(TINY[::2], TINY[1::2], strict=True)) | {option[0]: option[1]}
    assert main(["reproduce", "--out", str(out), *[a for kv in args.items() for a in kv]]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("cdpr-twin: error:") and option[0] in line, line
    assert _snapshot(out) == before  # the good report is not overwritten


def test_a_runs_scale_beyond_the_limit_is_refused():
    from cdpr_twin.study import plan

    with pytest.raises(ValueError, match="--runs-scale must be > 0 and ≤ 100"):
        plan(1000.0)  # 45 000 runs: a typo, not a study


def test_a_new_study_removes_the_earlier_ones_files_before_any_run(
    done_study, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "study"
    shutil.copytree(done_study, out)
    (out / "runs" / "open_loop_seed9").mkdir()  # an earlier, larger study's run
    (out / "runs" / "open_loop_seed9" / "summary.json").write_text(EARLIER_SUMMARY % "completed")
    (out / "runs" / "notes").mkdir()  # not a run of the study's: kept
    (out / "runs" / "notes" / "todo.txt").write_text("keep me\n")

    def interrupted(fn, specs, workers, runs_dir):
        raise KeyboardInterrupt  # Ctrl-C as the first run starts
        yield

    monkeypatch.setattr("cdpr_twin.campaign.executor.run_local", interrupted)
    assert main(["reproduce", "--out", str(out), *TINY]) == 130
    line = _one_line(capsys.readouterr().err)
    assert "interrupted" in line and "0 of 8 runs" in line and "no report" in line, line
    assert sorted(p.name for p in out.iterdir()) == ["runs", "study.json"]  # (its marker)
    assert [p.name for p in (out / "runs").iterdir()] == ["notes"]


def _children(pid: int) -> dict[int, str]:
    """The live child processes of ``pid`` (from /proc): pid → command line."""
    kids = {}
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(
                ln.split(":\t", 1) for ln in status.read_text().splitlines() if ":\t" in ln
            )
            cmd = (status.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if fields.get("PPid", "").strip() == str(pid) and not fields["State"].startswith("Z"):
            kids[int(status.parent.name)] = cmd
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text().split("State:\t", 1)[1]
    except (OSError, IndexError):
        return False
    return not state.startswith("Z")


def test_sigterm_stops_the_workers_and_leaves_no_stale_report(done_study, tmp_path):
    out = tmp_path / "study"
    shutil.copytree(done_study, out)  # the earlier study: its report must not survive
    err_path = tmp_path / "stderr.txt"
    with err_path.open("w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "cdpr_twin", "reproduce", "--out", str(out), *TINY],
            stdout=subprocess.DEVNULL,
            stderr=err,
            env={**os.environ, "MUJOCO_GL": "egl"},
        )
    try:
        deadline = time.monotonic() + 60
        while "[  1/8]" not in err_path.read_text():  # a run finished; the next is under way
            assert proc.poll() is None and time.monotonic() < deadline, err_path.read_text()
            time.sleep(0.05)
        children = _children(proc.pid)
        workers = [p for p, cmd in children.items() if "spawn_main" in cmd]
        assert workers, children
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 143
        assert not [p for p in workers if _alive(p)], "a worker outlived the study"
    finally:
        if proc.poll() is None:
            proc.kill()
    line = _one_line(err_path.read_text())
    assert "terminated" in line and "of 8 runs had finished" in line, line
    deadline = time.monotonic() + 5  # the rest (multiprocessing's resource tracker) follows
    while any(_alive(p) for p in children) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [p for p in children if _alive(p)], "a child process outlived the study"
    left = {p.name for p in out.iterdir()}
    assert left == {"runs", "study.json"}, left  # no report, runs.json or figure: old or new
    # the stopped study's directory is still a study's: a run is refused there (before, it
    # wrote its files beside runs/, and the next reproduce refused its own directory)
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "0.08", "--no-camera"]
    assert main(argv) == 2
    # before: the run under way kept its lock and *.partial files
    found = (out / "runs").rglob("*")
    assert not [p for p in found if p.name == ".lock" or p.suffix == ".partial"]


def _failing_scenario(tmp_path: Path) -> Path:
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = f'plugins = ["{Path(__file__).stem}"]\n' + text
    text = text.replace('passive = ["', 'passive = ["failing_midway", "', 1)
    path = tmp_path / "failing.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("traceback", [False, True], ids=["one line", "--traceback"])
def test_a_plugin_raising_mid_run_is_one_line(traceback, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["run", str(_failing_scenario(tmp_path)), "--out", str(out), "--no-camera"]
    assert main([*args, "--duration", "1", *(["--traceback"] if traceback else [])]) == 1
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed: RuntimeError: failing_midway: boom"
    if traceback:
        assert "Traceback" in err and "raise RuntimeError" in err
        err = err.split("RuntimeError: failing_midway: boom\n", 1)[1]  # the trace's last line
    line = _one_line(err)
    assert "RuntimeError: failing_midway: boom" in line and str(out) in line, line


def test_a_directory_that_is_no_studys_keeps_its_own_report(tmp_path, capsys):
    """Before: ``reproduce --out`` on a directory holding someone's ``report.md`` removed it
    within seconds (only an earlier study's files are promised to go)."""
    from cdpr_twin.study.output_dir import clear_earlier_study

    out = tmp_path / "mydocs"
    (out / "runs" / "open_loop_seed1").mkdir(parents=True)
    own = {"report.md": "my own report", "fig5a.png": "not a figure", "notes.txt": "mine"}
    for name, text in own.items():
        (out / name).write_text(text)
    assert main(["reproduce", "--out", str(out), *TINY]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "report.md, fig5a.png, runs/open_loop_seed1" in line and "another --out" in line
    assert {p.name: p.read_text() for p in out.iterdir() if p.is_file()} == own
    # a study's report.json (docs/ keeps no runs.json) makes it a study's: cleared
    (out / "report.json").write_text(json.dumps({"runs": [], "findings": []}))
    clear_earlier_study(out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "runs"]
    assert not list((out / "runs").iterdir())
