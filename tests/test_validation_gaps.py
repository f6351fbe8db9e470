"""Inputs that used to pass silently (issue 13, item 4): each is now a clear error or flag."""

from pathlib import Path

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.estimators.base import NON_FINITE_INPUT
from cdpr_twin.plugins import make_estimator
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.sim import SimulationError, Twin
from cdpr_twin.types import Measurement

ROOT = Path(__file__).resolve().parent.parent
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


def test_a_closed_twin_neither_steps_nor_senses():
    twin = Twin(camera=False, tension_noise_std=0.0)
    twin.reset(paper_pose("p1"))
    twin.close()
    for act in (
        lambda: twin.advance(0.04, np.zeros(8)),
        twin.sense,
        lambda: twin.reset(paper_pose("p1")),
    ):
        with pytest.raises(SimulationError, match="closed"):
            act()


@pytest.mark.parametrize(
    "name",
    ["control", "image", "model_simple", "model_elastic", "model_pulley", "model_elastic_pulley"],
)
def test_every_estimator_flags_a_nan_measurement_time_the_same_way(name, twin):
    twin.reset(paper_pose("p1"))
    good = twin.sense()
    est = make_estimator(name, twin.nominal_geometry)
    est.reset(paper_pose("p1"))
    first = est.update(good)
    bad = Measurement(float("nan"), good.cable_lengths, good.tensions)
    e = est.update(bad)
    assert not e.valid and NON_FINITE_INPUT in e.flags
    np.testing.assert_array_equal(e.T_base_platform, first.T_base_platform)
    assert est.update(good).T_base_platform is not None  # and it carries on
