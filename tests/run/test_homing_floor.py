"""The homing floor of open-loop accuracy: a robot whose geometry is known exactly still misses
p1 by its start error carried through the move, δ₁ = A(p1)⁺ A(p0) δ₀
(:func:`cdpr_twin.math.kinematics.start_error_transfer`), checked here against the simulated robot;
with the ``acrobot`` profile's homing repeatability that floor is above the self-calibration's 1 mm
goal, whatever the calibration."""

import tomllib
from pathlib import Path

import numpy as np
from conftest import EXACT_OPEN_LOOP

from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.math.kinematics import start_error_transfer
from cdpr_twin.math.se3 import pose_from_vector, so3_log
from cdpr_twin.robot.realism import profile
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import scenario_from_data
from cdpr_twin.sim import nominal_robot

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "scenarios" / "paper_open_loop.toml"
PERFECT = {**EXACT_OPEN_LOOP, "seed": 3}  # only homing differs (switched on below)


def _at_p1(homing: tuple[float, float]) -> tuple[np.ndarray, dict]:
    """Where the platform truly is at p1 (4, 4), and the run's summary."""
    data = tomllib.loads(SOURCE.read_text())
    for key, value in PERFECT.items():
        set_dotted(data, key, value)
    set_dotted(data, "realism.homing.position_std", homing[0])
    set_dotted(data, "realism.homing.rotation_std_deg", homing[1])
    summary = run(scenario_from_data(data, SOURCE), None).summary
    return pose_from_vector(summary["segment_ends"][0]["true_pose"]), summary


def _move() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nominal geometry, p0 and p1 of the paper's open-loop run."""
    scenario = scenario_from_data(tomllib.loads(SOURCE.read_text()), SOURCE)
    p1 = pose_from_vector([0.284, -0.197, 0.08, 0, 0, 0])
    return nominal_robot(scenario.model.file).geometry, scenario.start_pose, p1


def test_a_start_error_reaches_p1_as_the_first_order_transfer_predicts():
    geometry, p0, p1 = _move()
    exact, _ = _at_p1((0.0, 0.0))  # the model's own residual (elasticity, sag): ≈ 0.2 mm
    homed, summary = _at_p1((0.001, 0.2))
    assert np.allclose(pose_from_vector(summary["segment_ends"][0]["waypoint"]), p1)
    offset = summary["homing_offset"]
    d0 = np.r_[offset["position_m"], np.radians(offset["rotation_deg"])]
    assert 1e-3 < np.linalg.norm(d0[:3]) < 3e-3  # a typical draw (seed 3: 2.1 mm)
    predicted = start_error_transfer(geometry, p0, p1) @ d0
    moved = homed[:3, 3] - exact[:3, 3]
    turned = so3_log(homed[:3, :3] @ exact[:3, :3].T)
    np.testing.assert_allclose(moved, predicted[:3], atol=1.5e-4)  # of ≈ 2 mm
    np.testing.assert_allclose(turned, predicted[3:], atol=np.radians(0.03))


def test_the_acrobot_homing_repeatability_alone_misses_p1_by_more_than_1_mm():
    transfer = start_error_transfer(*_move())
    h = profile("acrobot").homing
    draws = np.random.default_rng(0).normal(size=(100_000, 6))
    d0 = draws * np.r_[[h.position_std] * 3, [h.rotation_std] * 3]
    miss = np.linalg.norm((d0 @ transfer.T)[:, :3], axis=1)
    median, p5, p95 = np.percentile(miss, [50, 5, 95]) * 1e3
    print(f"homing alone at p1: median {median:.2f} mm, 5-95 % {p5:.2f}-{p95:.2f} mm")
    assert median > 1.0  # the calibration's p1 goal is below what homing alone leaves
