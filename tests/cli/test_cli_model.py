"""``cdpr-twin model build`` and ``model workspace`` on bad input and full disks: a one-line
error (exit 2 for bad input, 1 for a failed write), checked before any work, and never a
half-written or stale file under a final name."""

import errno
import os
from pathlib import Path

import pytest
from conftest import ENOSPC

from cdpr_twin import cli
from cdpr_twin.robot.description import load_robot
from cdpr_twin.sim.mjcf_from_robot import model_texts

ROOT = Path(__file__).resolve().parents[2]
ACROBOT = ROOT / "models" / "acrobot" / "robot.toml"


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


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


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


@pytest.mark.parametrize(
    ("old", "new", "problem"),
    [
        (
            "tension_range_n = [2.0, 75.0]",
            "tension_range_n = [2.0, 2.5]",
            "platform.home_pose: no tension distribution with 2.0 N ≤ τ ≤ 2.5 N",
        ),
        # before: the frame's message without the file or the field
        ("home_pose = [0.112,", "home_pose = [5.0,", "platform.home_pose: reset pose at position"),
        # before: "quaternion [0. 0. 0. 0.] is zero or not finite", no file or field
        (
            "quat_wxyz = [0.0, 0.0, 0.0, 1.0]",
            "quat_wxyz = [0.0, 0.0, 0.0, 0.0]",
            "camera.quat_wxyz: must be a non-zero quaternion",
        ),
    ],
)
def test_what_model_build_refuses_names_the_description_and_field(
    tmp_path, capsys, old, new, problem
):
    import shutil

    from cdpr_twin.cli import main

    shutil.copytree(ROOT / "models" / "acrobot", tmp_path / "robot")
    desc = tmp_path / "robot" / "robot.toml"
    text = desc.read_text()
    assert old in text
    desc.write_text(text.replace(old, new, 1))
    assert main(["model", "build", str(desc), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{desc}: {problem}" in err
