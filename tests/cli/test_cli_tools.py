"""``cdpr-twin scenarios copy`` on bad input and a full disk: a one-line error (exit 2 for bad
input, 1 for a failed write), and never a half-written file under its final name."""

from pathlib import Path

import pytest
from conftest import ENOSPC

from cdpr_twin import cli

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


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
