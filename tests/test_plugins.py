"""A 7th estimator defined here, outside the package, runs through a scenario and `reproduce`.

``MidpointEstimator`` fuses two other estimators: it declares them as inputs and returns the
midpoint of their poses (translation average, rotation halfway along the geodesic), with a
covariance. The scenario files name this module in ``plugins``, so spawned workers import it
too; no package code knows it.
"""

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

from cdpr_twin import plugins
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.math import se3
from cdpr_twin.plugins import OptionError, option
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.types import Measurement, PoseEstimate

ROOT = Path(__file__).resolve().parent.parent


@dataclasses.dataclass(frozen=True)
class MidpointOptions:
    """Which two estimators to fuse."""

    of: tuple[str, ...] = option(("control", "model_elastic_pulley"))

    def __post_init__(self) -> None:
        if len(self.of) != 2:
            raise OptionError("of", f"must name two estimators, got {list(self.of)}")


@plugins.register
class MidpointEstimator(Estimator):
    """The midpoint of two other estimators' poses."""

    name = "midpoint"
    Options = MidpointOptions

    @property
    def inputs(self) -> tuple[str, ...]:
        return self.options.of

    def update(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate] = NO_INPUTS,
    ) -> PoseEstimate:
        a, b = (inputs[n].T_base_platform for n in self.options.of)
        R = a[:3, :3] @ se3.so3_exp(0.5 * se3.so3_log(a[:3, :3].T @ b[:3, :3]))
        self._T = se3.transform(R, 0.5 * (a[:3, 3] + b[:3, 3]))
        spread = np.concatenate([a[:3, 3] - b[:3, 3], se3.so3_log(a[:3, :3].T @ b[:3, :3])])
        cov = np.diag(0.25 * spread**2 + 1e-12)
        return PoseEstimate(measurement.time, self._T, covariance=cov)


def _with_midpoint(scenario: str, tmp_path: Path) -> Path:
    """A copy of a paper scenario that also runs the midpoint estimator."""
    text = (ROOT / "scenarios" / scenario).read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = f'plugins = ["{Path(__file__).stem}"]\n' + text
    text = text.replace('passive = ["', 'passive = ["midpoint", "', 1)
    text += '\n[estimators.midpoint]\nof = ["control", "model_elastic_pulley"]\n'
    path = tmp_path / scenario
    path.write_text(text)
    return path


def test_a_fusing_estimator_from_outside_the_package_runs_in_a_scenario(tmp_path):
    scenario = load_scenario(_with_midpoint("paper_open_loop.toml", tmp_path))
    scenario = scenario.with_overrides(duration=2.0, camera=False)
    assert "midpoint" in scenario.estimators.names
    out = tmp_path / "out"
    summary = run(scenario, out, record_rrd=False).summary
    assert "midpoint" in summary["estimators"]
    ts = Timeseries.load(out / "timeseries.csv")
    assert "midpoint" in ts.estimator_names
    # every row: the midpoint of the two inputs' recorded positions (independent arithmetic)
    mid = ts.poses("midpoint")[:, :3, 3]
    expected = 0.5 * (ts.poses("control")[:, :3, 3] + ts.poses("model_elastic_pulley")[:, :3, 3])
    np.testing.assert_allclose(mid, expected, atol=1e-12)
    _, rot_to_a = ts.deviation("midpoint", "control")
    _, rot_ab = ts.deviation("model_elastic_pulley", "control")
    np.testing.assert_allclose(rot_to_a, 0.5 * rot_ab, atol=1e-9)


def test_inputs_that_do_not_run_or_bad_options_are_scenario_errors(tmp_path):
    from cdpr_twin.run.runner import prepare

    path = _with_midpoint("paper_open_loop.toml", tmp_path)
    text = path.read_text()
    path.write_text(
        text.replace('"model_simple", ', "").replace(
            'of = ["control", "model_elastic_pulley"]', 'of = ["control", "model_simple"]'
        )
    )
    with pytest.raises(ScenarioError, match=r"'midpoint' reads \['model_simple'\], which do not"):
        prepare(load_scenario(path).with_overrides(camera=False)).close()
    path.write_text(
        text.replace('of = ["control", "model_elastic_pulley"]', 'of = ["image", "control"]')
    )
    with pytest.raises(ScenarioError, match="dropped because the camera is off"):
        prepare(load_scenario(path).with_overrides(camera=False)).close()
    path.write_text(text.replace('of = ["control", "model_elastic_pulley"]', 'of = ["control"]'))
    with pytest.raises(ScenarioError, match=r"estimators\.midpoint\.of: must name two"):
        load_scenario(path)


def test_plugin_names_cannot_shadow_run_file_columns():
    with pytest.raises(ValueError, match="cannot name"):

        @plugins.register
        class Plan(MidpointEstimator):
            name = "plan"


@pytest.mark.slow
def test_a_seventh_estimator_goes_through_reproduce(tmp_path):
    from cdpr_twin.study import reproduce

    scenarios = (
        _with_midpoint("paper_open_loop.toml", tmp_path),
        _with_midpoint("paper_pbvs.toml", tmp_path),
    )
    out = tmp_path / "study"
    rep = reproduce(out, workers=2, runs_scale=0.1, duration=3.0, scenarios=scenarios)
    records = json.loads((out / "runs.json").read_text())
    names = {r["name"] for r in records}
    assert "pbvs_midpoint_seed1" in names and len(records) == 1 + 8  # the six, fused, midpoint
    assert all(r["ok"] for r in records), [r["status"] for r in records if not r["ok"]]
    assert "midpoint" in rep["open_loop"]["estimators"]
    assert "midpoint" in rep["pbvs"]
    assert "midpoint" in (out / "report.md").read_text()


@pytest.mark.parametrize("make", ["missing", "dir", "file"])
def test_a_plugin_file_that_is_missing_or_a_directory_is_named_as_such(tmp_path, make):
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    scenario = tmp_path / "s.toml"
    text = text.replace('"../models/', f'"{ROOT}/models/')
    scenario.write_text('plugins = ["extra.py"]\n' + text)
    target = tmp_path / "extra.py"
    if make == "dir":
        target.mkdir()
    elif make == "file":  # the control: a module of that name imports, and the scenario loads
        target.write_text("VALUE = 1\n")
        assert load_scenario(scenario).plugins == ("extra.py",)
        return
    why = {"missing": "plugin file not found", "dir": "a directory, not a Python file"}[make]
    with pytest.raises(ScenarioError, match=f"plugins: cannot import: .*extra.py: {why}$"):
        load_scenario(scenario)


def test_a_module_name_that_is_a_file_beside_the_scenario_says_to_add_py(tmp_path):
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    scenario = tmp_path / "s.toml"
    scenario.write_text('plugins = ["beside_it"]\n' + text)
    with pytest.raises(ScenarioError, match=r"No module named 'beside_it'$"):
        load_scenario(scenario)  # no such file either: Python's words alone
    (tmp_path / "beside_it.py").write_text("VALUE = 1\n")
    with pytest.raises(ScenarioError, match=r"'beside_it'; beside_it\.py beside the scenario is"):
        load_scenario(scenario)
    scenario.write_text('plugins = ["beside_it.py"]\n' + text)
    assert load_scenario(scenario).plugins == ("beside_it.py",)


def test_register_refuses_what_could_not_run_and_build_checks_the_bounds():
    from cdpr_twin.controllers.base import Controller

    class NoStep(Estimator):  # abstract: neither _step() nor update() written
        name = "no_step"

    with pytest.raises(TypeError, match=r"NoStep: implement _step \(abstract in Estimator\)"):
        plugins.register(NoStep)

    class DuckTyped:  # the right attributes, not an Estimator
        kind, name, Options = "estimator", "duck_typed", MidpointOptions

        def update(self, measurement, inputs=NO_INPUTS): ...

    with pytest.raises(TypeError, match=r"an estimator must subclass cdpr_twin\.estimators\.base"):
        plugins.register(DuckTyped)
    with pytest.raises(ValueError, match=r"^an estimator named 'control' is already registered"):

        @plugins.register
        class Control(MidpointEstimator):
            name = "control"

    with pytest.raises(ValueError, match=r"^a controller named 'pbvs' is already registered"):

        @plugins.register
        class Pbvs(Controller):
            name = "pbvs"

            def reset(self, T): ...

            def command(self, measurement, estimate): ...

    @dataclasses.dataclass(frozen=True)
    class Bounded:
        after: int = option(3, minimum=0)
        angle: float = option(0.1, minimum=1.0, unit="deg")  # SI: ≥ 0.01745 rad

    @plugins.register
    class BoundedEstimator(MidpointEstimator):
        name = "bounded_estimator"
        Options = Bounded

        @property
        def inputs(self):
            return ()

    from cdpr_twin.sim import Twin

    g = Twin(camera=False).nominal_geometry
    plugins.build("estimator", "bounded_estimator", g, after=0, angle=0.02)  # the bounds hold
    with pytest.raises(ValueError, match=r"^bounded_estimator: after: must be ≥ 0 \(SI units\)"):
        plugins.build("estimator", "bounded_estimator", g, after=-1)
    with pytest.raises(ValueError, match=r"angle: must be ≥ 0\.0174533 \(SI units\), got 0\.01"):
        plugins.build("estimator", "bounded_estimator", g, angle=0.01)
