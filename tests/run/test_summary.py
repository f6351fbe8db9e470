"""``summary.json`` and the deviations it reports: a number that is undefined (an estimator that
lost its track) is null in the JSON and NaN in a campaign's table, counted, never dropped."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cdpr_twin import plugins
from cdpr_twin.campaign.table import flatten
from cdpr_twin.cli import main
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.math.se3 import pose_from_vector, rot_z, transform
from cdpr_twin.run.metrics import NON_FINITE_ESTIMATE, DeviationTrack, RunMetrics
from cdpr_twin.types import Measurement, PoseEstimate, TickRecord

ROOT = Path(__file__).resolve().parents[2]


@plugins.register
class LostMidwayEstimator(Estimator):
    """The start pose, then NaN from t > 0.22 s (a plugin that loses its track)."""

    name = "lost_midway"

    def update(self, measurement, inputs=NO_INPUTS):
        self._check_reset()
        T = self._T if measurement.time <= 0.22 else np.full((4, 4), np.nan)
        return PoseEstimate(measurement.time, T)


def _strict_json(text: str):
    """Parse as RFC 8259 JSON: ``NaN``/``Infinity`` (Python's extension) raise."""

    def refuse(token):
        raise ValueError(f"{token} is not JSON (RFC 8259)")

    return json.loads(text, parse_constant=refuse)


def test_an_undefined_number_is_null_in_summary_json_and_nan_in_the_table(tmp_path, capsys):
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = f'plugins = ["{Path(__file__).stem}"]\n' + text
    path = tmp_path / "lost.toml"
    path.write_text(text.replace('passive = ["', 'passive = ["lost_midway", "', 1))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-camera", "--duration", "0.6"]) == 0
    printed = capsys.readouterr().out
    assert "lost_midway" in printed and "nan" in printed  # the table printed, not a traceback
    summary = _strict_json((out / "summary.json").read_text())  # was: a bare NaN
    lost = summary["estimators"]["lost_midway"]
    assert lost["final_translation_m"] is None and lost["final_rotation_deg"] is None
    assert lost["flags"] == {NON_FINITE_ESTIMATE: 10} and lost["invalid_updates"] == 10
    assert lost["max_translation_time_s"] <= 0.22  # over the finite estimates only
    task = {"run_id": "r", "block": "b", "name": "n", "params": {}}
    row = flatten(task, {**summary, "estimators": {"lost_midway": lost}})
    assert math.isnan(row["est.lost_midway.final_t_m"])
    assert row["est.lost_midway.max_t_m"] == lost["max_translation_m"] > 0
    assert _strict_json(row["summary"])["estimators"]["lost_midway"]["final_rotation_deg"] is None


def test_a_nan_estimate_is_counted_invalid_not_dropped_from_the_deviations():
    track = DeviationTrack()
    T = np.eye(4)
    track.add(PoseEstimate(0.04, T), (0.001, 0.002))
    track.add(PoseEstimate(0.08, np.full((4, 4), np.nan)), (math.nan, math.nan))
    track.add(PoseEstimate(0.12, T), (0.003, 0.001))
    s = track.summary()
    assert s["invalid_updates"] == 1 and s["flags"] == {NON_FINITE_ESTIMATE: 1}
    assert s["max_translation_m"] == 0.003 and s["max_translation_time_s"] == 0.12
    assert s["rms_translation_m"] == pytest.approx(math.sqrt((0.001**2 + 0.003**2) / 2))
    track.add(PoseEstimate(0.16, np.full((4, 4), np.nan)), (math.nan, math.nan))
    assert math.isnan(track.summary()["final_translation_m"])  # the last estimate: none


def test_deviations_accounted_a_batch_at_a_time_are_each_ticks_own():
    # truth: an estimate T_true · (Rz(θ), d) is |d| and θ from the truth, whatever T_true is
    rng = np.random.default_rng(4)
    d = rng.uniform(0.001, 0.01, (8, 3))
    theta = rng.uniform(0.01, 0.5, 8)
    metrics = RunMetrics(("moved", "lost"), [], 0.04, batch=3)
    for k in range(8):
        t = 0.04 * k
        T_true = pose_from_vector(np.r_[rng.normal(0.0, 0.2, 3), rng.uniform(-90.0, 90.0, 3)])
        lost = np.full((4, 4), np.nan) if k == 5 else T_true
        estimates = {
            "moved": PoseEstimate(t, T_true @ transform(rot_z(theta[k]), d[k])),
            "lost": PoseEstimate(t, lost),
        }
        m = Measurement(t, np.ones(8), np.zeros(8))
        tick = TickRecord(t, m, estimates, None, None, T_true, np.zeros(8), None)
        assert tick.deviations["moved"] == pytest.approx((np.linalg.norm(d[k]), theta[k]), 1e-12)
        metrics.add(tick)
        if k == 3:  # asked for midway: the ticks so far (none counted twice after)
            so_far = metrics.estimators()["moved"]["final_translation_m"]
            assert so_far == pytest.approx(np.linalg.norm(d[3]), rel=1e-12)
    s = metrics.estimators()
    moved, lost = s["moved"], s["lost"]
    dt = np.linalg.norm(d, axis=1)
    assert moved["max_translation_m"] == pytest.approx(dt.max(), rel=1e-12)
    assert moved["max_translation_time_s"] == pytest.approx(0.04 * dt.argmax())
    assert moved["max_rotation_deg"] == pytest.approx(np.degrees(theta.max()), rel=1e-12)
    assert moved["final_translation_m"] == pytest.approx(dt[-1], rel=1e-12)
    assert moved["rms_translation_m"] == pytest.approx(np.sqrt(np.mean(dt**2)), rel=1e-12)
    assert lost["invalid_updates"] == 1 and lost["flags"] == {NON_FINITE_ESTIMATE: 1}
    assert lost["max_translation_m"] < 1e-15 and lost["final_translation_m"] < 1e-15
