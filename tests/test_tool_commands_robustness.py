"""The tool commands (`model build`, `model workspace`, `scenarios copy`, `calibrate`) on bad
input and full disks: a one-line error (exit 2 for bad input, 1 for a failed write), checked
before any work, and never a half-written or stale file under a final name."""

import builtins
import errno
import io
import os
from pathlib import Path

import pytest

from cdpr_twin import cli
from cdpr_twin.calibrate.solver import CalibrationError
from cdpr_twin.robot.description import load_robot
from cdpr_twin.sim.mjcf_from_robot import model_texts

ROOT = Path(__file__).resolve().parent.parent
ACROBOT = ROOT / "models" / "acrobot" / "robot.toml"
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
START = "pose = [0.112, -0.032, 0.301, -12, -10, 0]"
ENOSPC = "No space left on device"


class _FullFile:
    """A file on a disk with ``budget[0]`` bytes free: what does not fit raises ENOSPC."""

    def __init__(self, f, budget: list[int]) -> None:
        self._f, self._budget = f, budget

    def write(self, data):
        room = self._budget[0]
        if len(data) > room:
            self._f.write(data[:room])
            self._f.flush()
            self._budget[0] = 0
            raise OSError(errno.ENOSPC, ENOSPC)
        self._budget[0] -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._f.close()


@pytest.fixture
def full_disk(monkeypatch):
    """``full_disk(n)``: from now on the disk takes ``n`` more bytes (``open`` and sendfile)."""

    def fill(free: int) -> None:
        real, budget = io.open, [free]

        def fake_open(file, mode="r", *args, **kwargs):
            f = real(file, mode, *args, **kwargs)
            return _FullFile(f, budget) if any(c in mode for c in "wax+") else f

        def fake_sendfile(*args):
            raise OSError(errno.ENOSPC, ENOSPC)

        monkeypatch.setattr(io, "open", fake_open)
        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(os, "sendfile", fake_sendfile)

    return fill


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


# --- model build ----------------------------------------------------------------------------


def test_model_build_on_a_full_disk_renames_nothing(tmp_path, full_disk, capsys):
    out = tmp_path / "built"
    out.mkdir()
    for name in ("acrobot.xml", "scene.xml"):  # an earlier build's files: kept as they were
        (out / name).write_text("old")
    robot_xml, _ = model_texts(load_robot(ACROBOT), out)
    full_disk(len(robot_xml.encode()) + 4096)  # the robot fits, the scene is cut at 4 KiB
    code = cli.main(["model", "build", str(ACROBOT), "--out", str(out)])
    assert code == 1
    err = _error(capsys)
    assert "scene.xml" in err and ENOSPC in err
    assert sorted(p.name for p in out.iterdir()) == ["acrobot.xml", "scene.xml"]  # no partial
    assert all((out / n).read_text() == "old" for n in ("acrobot.xml", "scene.xml"))


def test_model_build_on_a_full_disk_leaves_no_file_in_a_new_directory(tmp_path, full_disk, capsys):
    out = tmp_path / "new"
    full_disk(10_000)
    assert cli.main(["model", "build", str(ACROBOT), "--out", str(out)]) == 1
    assert ENOSPC in _error(capsys)
    assert list(out.iterdir()) == []


def test_model_build_bad_out_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out, words in ((afile, "not a directory"), (afile / "sub", "cannot create")):
        assert cli.main(["model", "build", str(ACROBOT), "--out", str(out)]) == 2
        assert words in _error(capsys)
    readonly = tmp_path / "readonly"
    readonly.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, m, **k: Path(p) != readonly and real(p, m, **k))
    assert cli.main(["model", "build", str(ACROBOT), "--out", str(readonly)]) == 2
    assert "cannot write there" in _error(capsys)
    assert afile.read_text() == "x" and list(readonly.iterdir()) == []


# --- scenarios copy -------------------------------------------------------------------------


def test_scenarios_copy_on_a_full_disk_leaves_nothing_and_can_be_retried(
    tmp_path, monkeypatch, full_disk, capsys
):
    full_disk(100)  # the file is created, 100 bytes fit, then the disk is full
    code = cli.main(["scenarios", "copy", "paper_open_loop", str(tmp_path / "mine")])
    monkeypatch.undo()  # space freed: the retry must be accepted
    assert list((tmp_path / "mine").iterdir()) == []  # no 0-byte NAME.toml, no partial
    err = _error(capsys)
    assert "paper_open_loop.toml" in err and ENOSPC in err
    assert code == 1  # a failure while working, not bad input
    assert cli.main(["scenarios", "copy", "paper_open_loop", str(tmp_path / "mine")]) == 0
    assert (tmp_path / "mine" / "paper_open_loop.toml").read_text() == OPEN_LOOP


def test_scenarios_copy_into_a_file_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "afile").write_text("x")
    assert cli.main(["scenarios", "copy", "paper_open_loop", str(tmp_path / "afile")]) == 2
    assert "not a directory" in _error(capsys)


def test_scenarios_copy_into_an_empty_path_is_refused_not_taken_for_here(
    tmp_path, monkeypatch, capsys
):
    """An unset shell variable (``"$DIR"``): before, the scenario was copied into the cwd."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        cli.main(["scenarios", "copy", "paper_pbvs", ""])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "argument dir: is empty: give a directory" in err
    assert list(tmp_path.iterdir()) == []


# --- model workspace ------------------------------------------------------------------------


@pytest.fixture
def no_sampling(monkeypatch):
    """Sampling the workspace fails the test: bad input must be refused before it."""

    def refuse(*args, **kwargs):
        raise AssertionError("the workspace was sampled before the input was checked")

    monkeypatch.setattr("cdpr_twin.math.workspace.sample_workspace", refuse)


@pytest.mark.parametrize(
    ("spacing", "words"),
    [
        ("0", "finite number > 0"),
        ("-0.1", "finite number > 0"),
        ("nan", "finite number > 0"),
        ("inf", "finite number > 0"),
        ("5", "give less than 2.4 m"),
        ("1e-6", "give at least"),
    ],
)
def test_workspace_bad_spacing_is_refused_before_sampling(
    spacing, words, tmp_path, no_sampling, capsys
):
    out = tmp_path / "ws.png"
    code = cli.main(["model", "workspace", str(ACROBOT), "--spacing", spacing, "--out", str(out)])
    assert code == 2
    err = _error(capsys)
    assert err.startswith("cdpr-twin: error: --spacing") and words in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("out", "words"),
    [
        ("nodir/ws.png", "nodir does not exist"),
        ("afile/ws.png", "afile is not a directory"),
        ("ws.txt", "cannot write a figure as .txt"),
        ("ws", "without an extension"),
        (".", "is a directory"),
    ],
)
def test_workspace_bad_out_is_refused_before_sampling(out, words, tmp_path, no_sampling, capsys):
    (tmp_path / "afile").write_text("x")
    code = cli.main(["model", "workspace", str(ACROBOT), "--out", str(tmp_path / out)])
    assert code == 2
    err = _error(capsys)
    assert "--out" in err and words in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


@pytest.mark.parametrize(
    ("flag", "why"), [(0, "Permission denied"), (os.ST_RDONLY, "Read-only file system")]
)
def test_workspace_out_in_an_unwritable_directory_is_refused_before_sampling(
    flag, why, tmp_path, monkeypatch, no_sampling, capsys
):
    """Before, the sampling ran (~40 s at the default spacing), then the figure's write failed
    (exit 1, "free some space"). As root chmod forbids nothing: the OS's answer is patched."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real_access, real_statvfs = os.access, os.statvfs
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != ro and real_access(p, mode))
    stat = real_statvfs(tmp_path)
    fake = os.statvfs_result((*stat[:8], stat.f_flag | flag, stat.f_namemax))
    monkeypatch.setattr(os, "statvfs", lambda p: fake if Path(p) == ro else real_statvfs(p))
    code = cli.main(["model", "workspace", str(ACROBOT), "--out", str(ro / "ws.png")])
    assert code == 2
    assert _error(capsys) == (
        f"cdpr-twin: error: --out {ro / 'ws.png'}: cannot write in {ro} ({why}); "
        "give another directory"
    )
    assert list(ro.iterdir()) == []


def test_workspace_figure_on_a_full_disk_keeps_the_earlier_one(tmp_path, monkeypatch, capsys):
    out = tmp_path / "ws.png"
    out.write_bytes(b"earlier figure")

    def savefig(self, fname, **kwargs):  # 4 KiB of the figure fit, then the disk is full
        with open(fname, "wb") if isinstance(fname, str | os.PathLike) else fname as f:
            f.write(b"\x89PNG" + bytes(4092))
        raise OSError(errno.ENOSPC, ENOSPC)

    monkeypatch.setattr("matplotlib.figure.Figure.savefig", savefig)
    code = cli.main(["model", "workspace", str(ACROBOT), "--spacing", "0.6", "--out", str(out)])
    assert code == 1
    err = _error(capsys)
    assert "ws.png" in err and ENOSPC in err
    assert out.read_bytes() == b"earlier figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ws.png"]  # no partial


def test_workspace_writes_a_whole_figure(tmp_path, capsys):
    out = tmp_path / "ws.svg"
    code = cli.main(["model", "workspace", str(ACROBOT), "--spacing", "0.6", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert "grid points wrench-feasible" in capsys.readouterr().out
    assert out.read_text().rstrip().endswith("</svg>")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ws.svg"]


# --- calibrate ------------------------------------------------------------------------------


@pytest.fixture
def no_recording(monkeypatch):
    """Recording (a worker process, or in this one) fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError("the recording started before the input was checked")

    monkeypatch.setattr("cdpr_twin.calibrate.acquire.ProcessPoolExecutor", refuse)
    monkeypatch.setattr("cdpr_twin.calibrate.session.record", refuse)


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

    monkeypatch.setattr("cdpr_twin.calibrate.session.calibrate", fail)
    out = tmp_path / "runs" / "cal"
    assert cli.main(["calibrate", "paper_open_loop", "--poses", "12", "--out", str(out)]) == 2
    assert "never detected" in _error(capsys)
    assert not (tmp_path / "runs").exists()  # neither it nor the parent it made
    mine = tmp_path / "mine"  # a directory the user made is kept, with what it held
    mine.mkdir()
    (mine / "notes.txt").write_text("x")
    assert cli.main(["calibrate", "paper_open_loop", "--poses", "12", "--out", str(mine)]) == 2
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
