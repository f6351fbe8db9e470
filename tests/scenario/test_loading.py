"""Scenario files read and checked: a value that would hang a run, do nothing or name a file
wrongly is refused in one line naming the file and the field."""

import tomllib
from pathlib import Path

import pytest

from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.scenario.loading import ScenarioError, load_scenario, scenario_from_data

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()


def _file(tmp_path, old, new):
    assert old in OPEN_LOOP
    path = tmp_path / "s.toml"
    path.write_text(OPEN_LOOP.replace('"../models/', f'"{ROOT}/models/').replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("timestep = 0.0005", "timestep = 1e-9", "model.timestep: must be ≥ 1e-05"),
        ("timestep = 0.0005", "timestep = 0.005", "model.timestep: must be ≤ 0.002"),
        ("durations = [10.0, 5.0, 10.0]", "durations = [10.0, inf, 10.0]", "durations[1]"),
        ("duration = 25.0", "duration = 0.01", "duration: 0.01 s must span 1"),
    ],
)
def test_scenario_values_that_would_hang_or_do_nothing_are_refused(tmp_path, old, new, field):
    with pytest.raises(ScenarioError, match=field.replace("[", r"\[").replace("]", r"\]")):
        load_scenario(_file(tmp_path, old, new))


def test_a_bad_truth_value_names_the_file_and_the_field_once(tmp_path):
    # before: "s.toml: truth: s.toml: truth.exit_point_std: must be ≥ 0 m, got -0.012"
    path = _file(tmp_path, "exit_point_std = 0.012 ", "exit_point_std = -0.012 ")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message == f"{path}: truth.exit_point_std: must be ≥ 0 m, got -0.012"


@pytest.mark.parametrize("command", ["run", "calibrate"])
@pytest.mark.parametrize(
    "escaped", [r"a\u0000b", r"a\nb", r"a\tb", r"a\u007fb"], ids=["NUL", "newline", "tab", "DEL"]
)
def test_a_scenario_name_with_a_control_character_is_refused_naming_the_field(
    escaped, command, tmp_path, monkeypatch, capsys
):
    """Before: NUL was "the run failed: ValueError" (exit 1, a traceback from calibrate), a
    newline made the directory ``runs/a⏎b``."""
    from cdpr_twin.cli import main

    path = _file(tmp_path, 'name = "paper_open_loop"', f'name = "{escaped}"')
    monkeypatch.chdir(tmp_path)  # the default output directory: runs/<name>
    assert main([command, str(path), "--no-camera" if command == "run" else "--poses=12"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"{path}: name: must be a plain name" in err and "control characters" in err
    assert [p.name for p in tmp_path.iterdir()] == ["s.toml"]


def test_a_run_shorter_than_one_control_period_is_refused_on_the_command_line():
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    with pytest.raises(ScenarioError, match=r"--duration: 0\.001 s must span 1"):
        s.with_overrides(duration=0.001)


def test_an_unknown_optional_field_lists_the_fields_it_could_be():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "realism.camera.exposure_ms", 4.0)  # was: "known fields here: none"
    with pytest.raises(ScenarioError, match=r"exposure_ms: unknown field; known .*exposure_s"):
        scenario_from_data(data, source)


def test_a_typo_in_model_lists_the_optional_fields_too():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "model.nomnal", "x.toml")
    with pytest.raises(ScenarioError, match=r"model\.nomnal: unknown field; .*nominal"):
        scenario_from_data(data, source)
