"""``cdpr-twin model build`` and ``model workspace`` on bad input and full disks: a one-line
error (exit 2 for bad input, 1 for a failed write), checked before any work, and never a
half-written or stale file under a final name."""

import errno
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


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
