"""Refusals of command-line options: one line naming what the user gave (an option, or a
scenario file's field), exit 2, no traceback, nothing written."""

from pathlib import Path

import pytest

from cdpr_twin.cli import main

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


def _scenario(tmp_path: Path, in_loop: str, camera: str) -> Path:
    path = tmp_path / "s.toml"
    text = OPEN_LOOP.replace('in_loop = "control"', f'in_loop = "{in_loop}"')
    path.write_text(text.replace("camera = true", f"camera = {camera}"))
    return path


@pytest.mark.parametrize(
    ("in_loop", "camera", "options", "says", "not_said"),
    [
        # both from the command line: before, the file's estimators.in_loop was blamed
        (
            "control",
            "true",
            ["--in-loop", "image", "--no-camera"],
            ["--in-loop image needs the camera", "--no-camera turned it off"],
            "estimators.",
        ),
        (
            "image",
            "true",
            ["--no-camera"],
            ["--no-camera", "estimators.in_loop: 'image' needs the camera"],
            "--in-loop image",
        ),
        (
            "control",
            "false",
            ["--in-loop", "image"],
            ["--in-loop image needs the camera", "sensors.camera = false"],
            "--no-camera",
        ),
        # the file's own conflict: its field, as before
        (
            "image",
            "false",
            [],
            ["s.toml: estimators.in_loop: 'image' needs the camera"],
            "--",
        ),
    ],
    ids=["both_options", "no_camera_option", "in_loop_option", "the_file"],
)
def test_in_loop_without_camera_names_who_asked(
    in_loop, camera, options, says, not_said, tmp_path, capsys
):
    out = tmp_path / "out"
    scenario = _scenario(tmp_path, in_loop, camera)
    assert main(["run", str(scenario), *options, "--out", str(out)]) == 2
    err = _error(capsys)
    assert err.startswith("cdpr-twin: error: ")
    assert all(s in err for s in says), err
    assert not_said not in err.removeprefix("cdpr-twin: error: "), err
    assert not out.exists()


def test_pbvs_without_camera_names_the_option(tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        main(["run", str(ROOT / "scenarios" / "paper_pbvs.toml"), "--no-camera", "--out", str(out)])
        == 2
    )
    err = _error(capsys)
    assert "--no-camera" in err and "controller.type: 'pbvs' needs the camera" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--seed", "-5", "--seed must be an integer ≥ 0, got -5"),  # was numpy's words only
        ("--noise", "-1", "--noise must be a tension noise std ≥ 0 N, got -1.0"),
        ("--noise", "nan", "--noise must be a tension noise std ≥ 0 N, got nan"),
    ],
)
def test_demo_option_out_of_range_names_the_option(option, value, says, capsys):
    assert main(["demo", option, value]) == 2
    assert _error(capsys) == f"cdpr-twin demo: error: {says}"
    assert capsys.readouterr().out == ""
