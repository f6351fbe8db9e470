"""The repeatability decomposition and the extra runs of the study, on known numbers."""

from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.robot.realism import RUN_SOURCES
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.study.plan import extra_runs, plan
from cdpr_twin.study.repeatability import spread

ROOT = Path(__file__).resolve().parents[2]


def _records(errors: dict[str, list[float]]):
    """Runs whose final error at p1 is given, by group; accuracy read from a lookup table."""
    records, table = [], {}
    for group, values in errors.items():
        for k, e in enumerate(values):
            name = f"{group}-{k}"
            without = [group[len("without ") :]] if group.startswith("without ") else []
            records.append(
                {
                    "name": name,
                    "kind": "open_loop",
                    "ok": True,
                    "status": "done",
                    "dir": name,
                    "without": without,
                    "goal": None,
                    "in_loop": None,
                }
            )
            table[name] = {"translation_m": e, "rotation_deg": 10 * e}
    return records, lambda run_dir, kind, p1: table[str(run_dir)]


def test_variance_shares_are_what_each_source_leaves_out():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0, 2e-4, 40), rng.normal(0, 1e-4, 40)  # two independent sources
    records, accuracy = _records({"all": list(5e-3 + a + b), "without pixel_noise": list(5e-3 + b)})
    out = spread(records, accuracy, None)["open loop"]
    v_all, v_wo = np.var(a + b, ddof=1), np.var(b, ddof=1)
    assert out["all"]["n"] == 40
    assert out["all"]["std_translation_m"] == pytest.approx(np.sqrt(v_all), rel=1e-12)
    share = out["without pixel_noise"]["variance_share_translation_m"]
    assert share == pytest.approx(1 - v_wo / v_all, rel=1e-12)
    assert 0.6 < share < 0.95  # ≈ 0.8 = 4 / (4 + 1) in expectation


def test_the_study_repeats_open_loop_and_control_runs_for_each_source_and_goal():
    specs = plan(runs_scale=0.2)  # 2 open-loop runs, 1 PBVS run per estimator
    extra = extra_runs(specs, RUN_SOURCES, goal="taught")
    base = [s for s in specs if s.kind == "open_loop" or s.in_loop == "control"]
    assert len(extra) == len(RUN_SOURCES) * len(base) + 1
    assert {s.group for s in extra} == {
        *(f"without {src}" for src in RUN_SOURCES),
        "goal taught",
    }
    assert all(not s.record_rrd for s in extra)


def test_switching_a_source_off_touches_that_source_only():
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml")
    assert s.realism.profile == "acrobot" and s.realism.camera.noise
    quiet = s.without("pixel_noise")
    assert not quiet.realism.camera.noise
    assert quiet.realism.camera.exposure_s == s.realism.camera.exposure_s
    assert s.without("homing").realism.homing.position_std == 0.0
    t = s.without("tension_noise")
    assert t.realism.tension.noise_std == 0.0 and t.sensors.tension_noise_std == 0.0
    # per robot, kept (nan: the robot's accuracy a/√3, filled in by the sensors)
    np.testing.assert_equal(t.realism.tension.bias_std, s.realism.tension.bias_std)
    assert t.overrides["without"] == ["tension_noise"]
    with pytest.raises(ScenarioError, match="unknown source"):
        s.without("gremlins")
