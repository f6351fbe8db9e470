"""Outputs never written through a symbolic link, and only our own files ever removed.

A link planted at a ``*.partial`` name or at a final name, pointing at a file outside the
output directory, before a command or in the middle of it (a race, made deterministic by a
hook on ``os.open``): the target keeps its bytes and its modification time, and the final
name is our regular file, or the command refuses in one line.
"""

import errno
import json
import os
import stat
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import EARLIER_SUMMARY

from cdpr_twin.cli import main
from cdpr_twin.files.transaction import OutputDir, OutputError, write_atomic

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = ROOT / "scenarios" / "paper_open_loop.toml"
ACROBOT = ROOT / "models" / "acrobot" / "robot.toml"
RUN = ["--no-camera", "--duration", "0.2"]


@dataclass(frozen=True)
class Victim:
    """A file outside every output directory (a link's target), with its bytes and mtime."""

    path: Path
    mtime_ns: int

    def __fspath__(self) -> str:
        return str(self.path)

    def __str__(self) -> str:
        return str(self.path)

    def untouched(self) -> bool:
        """Whether it holds its bytes and its modification time still."""
        return (
            self.path.read_bytes() == b"precious\n"
            and self.path.stat().st_mtime_ns == self.mtime_ns
        )


@pytest.fixture
def victim(tmp_path) -> Victim:
    path = tmp_path / "victim.txt"
    path.write_bytes(b"precious\n")
    os.utime(path, ns=(1_000_000_000, 1_000_000_000))
    return Victim(path, os.stat(path).st_mtime_ns)


def _plant(link: Path, target: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target)


def _regular(path: Path) -> bool:
    return stat.S_ISREG(os.lstat(path).st_mode)


def _one_line(err: str) -> str:
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    return err.strip()


def _plant_at_open(monkeypatch, name: str, target: Path, times: int) -> list[int]:
    """Plant a link at ``name`` just before each of the first ``times`` ``os.open`` of it."""
    real, planted = os.open, [0]

    def planting_open(path, flags, *args, **kwargs):
        if Path(path).name == name and planted[0] < times:
            planted[0] += 1
            Path(path).symlink_to(target)
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", planting_open)
    return planted


# --- run ------------------------------------------------------------------------------------


def test_a_run_writes_no_file_through_links_planted_before_it(tmp_path, victim, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text(EARLIER_SUMMARY % "completed")  # an earlier run's
    for name in ("recording.rrd.partial", "summary.json.partial"):
        _plant(out / name, victim)
    _plant(out / "timeseries.csv.partial", tmp_path / "made_outside.csv")  # dangling
    _plant(out / "timeseries.csv", victim)  # a final name
    _plant(out / "recording.rrd", tmp_path / "nowhere")  # a dangling one
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 0, capsys.readouterr().err
    assert victim.untouched() and not os.path.lexists(tmp_path / "made_outside.csv")
    assert sorted(p.name for p in out.iterdir()) == [
        "recording.rrd",
        "summary.json",
        "timeseries.csv",
    ]
    assert all(_regular(p) for p in out.iterdir())
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"


def test_a_run_refuses_a_link_at_a_final_name_no_run_of_ours_left(tmp_path, victim, capsys):
    out = tmp_path / "out"
    _plant(out / "timeseries.csv", victim)
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "timeseries.csv" in line and "choose another --out" in line
    assert victim.untouched() and os.readlink(out / "timeseries.csv") == str(victim)
    assert [p.name for p in out.iterdir()] == ["timeseries.csv"]  # no lock left


def test_a_link_planted_again_during_the_run_fails_it_in_one_line(
    tmp_path, victim, monkeypatch, capsys
):
    out = tmp_path / "out"
    _plant_at_open(monkeypatch, "timeseries.csv.partial", victim, times=2)
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "timeseries.csv.partial" in line and "another program" in line
    assert victim.untouched()
    assert not (out / "timeseries.csv").exists() and not (out / "summary.json").exists()


def test_a_link_planted_once_during_the_run_is_replaced_not_followed(
    tmp_path, victim, monkeypatch, capsys
):
    out = tmp_path / "out"
    planted = _plant_at_open(monkeypatch, "recording.rrd.partial", victim, times=1)
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 0, capsys.readouterr().err
    assert planted == [1] and victim.untouched()
    assert _regular(out / "recording.rrd") and (out / "recording.rrd").stat().st_size > 1000


# --- only our own files are removed -----------------------------------------------------------


def test_a_scenario_named_as_an_output_is_refused_and_kept(tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    text = OPEN_LOOP.read_text().replace(
        'file = "../models/acrobot/scene.xml"', f'file = "{ROOT / "models/acrobot/scene.xml"}"'
    )
    (out / "timeseries.csv").write_text(text)
    before = (out / "timeseries.csv").read_bytes()
    assert main(["run", str(out / "timeseries.csv"), "--out", str(out), *RUN]) == 2
    assert "is an input of this command" in _one_line(capsys.readouterr().err)
    assert (out / "timeseries.csv").read_bytes() == before
    assert [p.name for p in out.iterdir()] == ["timeseries.csv"]


@pytest.mark.parametrize("foreign", ['{"x": 1}\n', "not json\n", '{"status": "done"}\n'])
def test_a_summary_json_not_ours_is_refused_and_kept(tmp_path, capsys, foreign):
    home = tmp_path / "home"
    home.mkdir()
    (home / "summary.json").write_text(foreign)
    assert main(["run", str(OPEN_LOOP), "--out", str(home), *RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "summary.json" in line and "no earlier run of ours wrote" in line
    assert (home / "summary.json").read_text() == foreign
    assert [p.name for p in home.iterdir()] == ["summary.json"]


def test_a_claim_removes_dangling_links_at_its_names_and_no_target(tmp_path, victim):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text(EARLIER_SUMMARY % "completed")
    _plant(out / "timeseries.csv.partial", tmp_path / "nowhere")
    _plant(out / "recording.rrd", victim)
    owner = OutputDir(out)
    owner.claim()
    owner.release()
    assert list(out.iterdir()) == [] and victim.untouched()


# --- edges of the output directory -------------------------------------------------------------


def test_a_full_disk_at_the_lock_leaves_no_directory_and_no_lock(tmp_path, monkeypatch, capsys):
    def full(fd, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "write", full)
    out = tmp_path / "new" / "out"
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(out) in line and os.strerror(errno.ENOSPC) in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["timeseries.csv", "summary.json", "recording.rrd.partial"])
def test_a_directory_at_an_output_name_is_refused_untouched(tmp_path, capsys, name):
    out = tmp_path / "out"
    (out / name).mkdir(parents=True)
    (out / name / "inside").write_text("mine")
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.endswith(f"{out / name} is a directory; remove it or choose another --out")
    assert "partial" not in line.replace(name, "")
    assert [p.name for p in out.iterdir()] == [name]
    assert (out / name / "inside").read_text() == "mine"


def test_a_dangling_link_as_out_is_named_so(tmp_path, capsys):
    out = tmp_path / "out"
    out.symlink_to(tmp_path / "gone")
    assert main(["run", str(OPEN_LOOP), "--out", str(out), *RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "is a dangling symbolic link" in line and "File exists" not in line
    assert os.path.islink(out) and not (tmp_path / "gone").exists()


# --- the other commands -------------------------------------------------------------------------


def test_scenarios_copy_writes_through_no_link(tmp_path, victim, monkeypatch, capsys):
    _plant(tmp_path / "d" / "paper_open_loop.toml.partial", victim)
    assert main(["scenarios", "copy", "paper_open_loop", str(tmp_path / "d")]) == 0
    copied = tmp_path / "d" / "paper_open_loop.toml"
    assert victim.untouched() and _regular(copied)
    assert copied.read_bytes() == OPEN_LOOP.read_bytes()
    _plant_at_open(monkeypatch, "paper_pbvs.toml.partial", victim, times=2)
    assert main(["scenarios", "copy", "paper_pbvs", str(tmp_path / "d")]) == 1
    assert "another program" in _one_line(capsys.readouterr().err)
    assert victim.untouched() and not (tmp_path / "d" / "paper_pbvs.toml").exists()


def test_model_build_writes_through_no_link(tmp_path, victim, monkeypatch):
    out = tmp_path / "built"
    _plant(out / "acrobot.xml.partial", victim)
    _plant(out / "scene.xml", victim)
    planted = _plant_at_open(monkeypatch, "scene.xml.partial", victim, times=1)
    assert main(["model", "build", str(ACROBOT), "--out", str(out)]) == 0
    assert planted == [1] and victim.untouched()
    assert sorted(p.name for p in out.iterdir()) == ["acrobot.xml", "scene.xml"]
    assert all(_regular(p) for p in out.iterdir())
    assert "<mujoco" in (out / "scene.xml").read_text()


def test_a_calibrations_files_are_written_through_no_link(tmp_path, victim, monkeypatch):
    from cdpr_twin.calibrate import output

    monkeypatch.setattr(output, "calibrated_description", lambda *a, **k: "# robot\n")
    monkeypatch.setattr(output, "report", lambda *a: {"fit": 1})
    _plant(tmp_path / "calibrated_robot.toml.partial", victim)
    _plant(tmp_path / "calibration.json", victim)
    _plant_at_open(monkeypatch, "calibration.json.partial", victim, times=1)
    robot, rep = output.write(tmp_path, tmp_path / "robot.toml", None, {}, None)
    assert victim.untouched() and _regular(robot) and _regular(rep)
    assert robot.read_text() == "# robot\n" and json.loads(rep.read_text()) == {"fit": 1}


def test_a_calibration_refuses_a_report_not_ours(tmp_path, capsys):
    (tmp_path / "calibration.json").write_text("{}")
    argv = ["calibrate", "paper_open_loop", "--out", str(tmp_path), "--poses", "12"]
    assert main(argv) == 2
    assert "no calibration.json of ours" in _one_line(capsys.readouterr().err)
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.json"]


def _campaign_file(tmp_path: Path) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(
        f'name = "c"\nscenario = "{OPEN_LOOP}"\n\n[overrides]\n"sensors.camera" = false\n'
        "duration = 0.2\n"
    )
    return path


def test_a_campaign_writes_through_no_link(tmp_path, victim, monkeypatch, capsys):
    out = tmp_path / "out"
    for name in ("campaign.json.partial", "results.parquet.partial", "report.md.partial"):
        _plant(out / name, victim)
    _plant(out / "parts" / "part-00001.parquet.partial", victim)
    planted = _plant_at_open(monkeypatch, "distribution.png.partial", victim, times=1)
    code = main(["campaign", str(_campaign_file(tmp_path)), "--out", str(out), "--workers", "1"])
    assert code == 0, capsys.readouterr().err
    assert planted == [1] and victim.untouched()
    for name in ("campaign.json", "results.parquet", "report.md", "distribution.png"):
        assert _regular(out / name), name
    assert _regular(out / "parts" / "part-00001.parquet")
    assert not any(p.name.endswith(".partial") for p in out.rglob("*"))


def test_a_campaign_refuses_a_report_not_ours(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.md").write_text("my report\n")
    assert main(["campaign", str(_campaign_file(tmp_path)), "--out", str(out)]) == 2
    assert "no campaign.json of ours" in _one_line(capsys.readouterr().err)
    assert [p.name for p in out.iterdir()] == ["report.md"]


def test_a_study_writes_its_marker_through_no_link(tmp_path, victim, monkeypatch, capsys):
    out = tmp_path / "study"
    _plant(out / "study.json.partial", victim)
    _plant_at_open(monkeypatch, "study.json.partial", victim, times=1)

    def interrupted(fn, specs, workers, runs_dir):
        raise KeyboardInterrupt  # Ctrl-C as the first run starts
        yield

    monkeypatch.setattr("cdpr_twin.campaign.executor.run_local", interrupted)
    argv = ["reproduce", "--out", str(out), "--duration", "0.2", "--runs-scale", "0.01"]
    assert main(argv) == 130
    assert victim.untouched() and _regular(out / "study.json")
    assert json.loads((out / "study.json").read_text())["command"] == "reproduce"


def test_write_atomic_replaces_a_link_at_the_final_name(tmp_path, victim):
    _plant(tmp_path / "report.md", victim)
    write_atomic(tmp_path / "report.md", "ours\n")
    assert victim.untouched() and _regular(tmp_path / "report.md")
    assert (tmp_path / "report.md").read_text() == "ours\n"


def test_a_partial_replaced_while_written_is_not_renamed(tmp_path, victim):
    from cdpr_twin.files.transaction import Partial

    out = Partial(tmp_path / "x.json")
    os.unlink(out.partial)
    out.partial.symlink_to(victim)  # another program swapped it under us
    with pytest.raises(OutputError, match="replaced by another file"):
        out.commit()
    assert victim.untouched() and not (tmp_path / "x.json").exists()
