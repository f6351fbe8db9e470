"""Homing each drum on its own: the start pose is the elastic equilibrium the cables hold.

The prediction is computed here, independently of MuJoCo: the pose where the platform's weight
balances the cables' elastic forces τ_i = max(0, E·S/l0_i·(L_i − l0_i)) (the math package's
pulley kinematics and Jacobian, scipy's least squares), the slack cables left out by the max.
A 0.6 mm error on a cable of E·S/l ≈ 3e5 N/m is ≈ 180 N against the 2–10 N it carries, so some
cables go slack: the linear prediction over all eight (K⁻¹ of the all-taut stiffness) misses by
far more than the tolerance, which the last check shows.
"""

import dataclasses
from pathlib import Path

import numpy as np
from conftest import paper_pose
from scipy.optimize import least_squares, minimize

from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.math.statics import tension_distribution
from cdpr_twin.robot.realism import DriveRealism, run_rng
from cdpr_twin.run.runner import prepare, start
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import build_robot

ROOT = Path(__file__).resolve().parents[2]
STD = 0.0006  # [m] the acrobot_full profile's drum zero error


def _pose(T0, x):
    T = np.array(T0, dtype=float)
    T[:3, :3] = se3.so3_exp(x[3:]) @ T[:3, :3]
    T[:3, 3] += x[:3]
    return T


def _equilibrium(g, l0, T0):
    """The pose where the elastic cables hold the platform's weight, and their tensions.

    The stable equilibrium is the minimum of the potential energy Σ ½ k_i max(0, L_i − l0_i)²
    − m g·c (k_i = E·S/l0_i, c the centre of mass), smooth through a cable's going slack; a
    least-squares solve of the wrench balance then polishes it to rounding.
    """
    k = g.es / l0

    def stretch(T):
        return np.maximum(0.0, kin.cable_lengths(g, T, "pulley") - l0)

    def energy(x):
        T = _pose(T0, x)
        com = T[:3, :3] @ g.com_platform + T[:3, 3]
        return 0.5 * np.sum(k * stretch(T) ** 2) - g.mass * (g.gravity @ com)

    def residual(x):
        T = _pose(T0, x)
        A = kin.jacobian(g, T, "base", "pulley")  # L̇ = A·[v, ω] (F_b): a cable pulls with −Aᵀτ
        return -A.T @ (k * stretch(T)) + kin.gravity_wrench(g, T)

    x = minimize(energy, np.zeros(6), method="BFGS", options={"gtol": 1e-9}).x
    x = least_squares(residual, x, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    T = _pose(T0, x)
    return T, k * stretch(T)


def _wound(g, T):
    tau = tension_distribution(g, T, *g.tension_bounds(None, None))
    return kin.rest_lengths(kin.cable_lengths(g, T, "pulley"), tau, g.es)


def test_the_platform_settles_where_the_taut_cables_hold_it():
    p = build_robot().physics
    g, T0 = p.geometry, paper_pose("p0")
    errors = np.random.default_rng(1).normal(0.0, STD, p.n_cables)
    l0 = _wound(g, T0) + errors
    p.settle_at_lengths(l0, T0)
    T_pred, tau_pred = _equilibrium(g, l0, T0)
    slack = tau_pred == 0.0
    assert 0 < slack.sum() <= 4  # some cables slack, the rest hold the platform
    assert np.array_equal(p.tensions == 0.0, slack)
    dp, dtheta = se3.pose_distance(T_pred, p.T_base_platform)
    # MuJoCo's wrapped tendon against the closed-form pulley model agree to rounding; the 2 s
    # settle leaves the slowest mode at e⁻⁸ of its start (≈ 0.3 µm of 1 mm; measured: 1e-13 m)
    assert dp < 1e-8 and dtheta < 1e-7
    assert np.allclose(p.tensions, tau_pred, atol=5e-3)  # 1e-8 m × 3.5e5 N/m
    # the move is of the errors' size, and the linear all-taut prediction is far off it
    moved = se3.pose_distance(T0, p.T_base_platform)[0]
    assert moved > 1e-4
    K = kin.stiffness_matrix(g, T0, l0)
    A = kin.jacobian(g, T0, "base", "pulley")
    linear = np.linalg.solve(K, A.T @ (g.es / l0 * errors))  # all cables taut: K δx = Aᵀ k δ
    assert np.linalg.norm(linear[:3] - (p.T_base_platform[:3, 3] - T0[:3, 3])) > 1e-5


def test_a_run_homed_by_drums_starts_where_they_settle_and_believes_the_start_pose():
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").with_realism("ideal")
    s = s.with_overrides(camera=False, duration=0.08)
    drive = DriveRealism(zero_error_std=STD)
    s = dataclasses.replace(s, realism=dataclasses.replace(s.realism, drive=drive))
    setup = prepare(s)
    try:
        errors = run_rng(s.seed, "drive").normal(0.0, STD, setup.physics.n_cables)
        assert np.array_equal(setup.drum_zero_errors, errors)
        start(setup)
        # the true cables are the true robot's rest lengths at the start pose plus each drum's
        # error; the encoders read the nominal model's (the robot believes it stands there)
        true_g = setup.physics.geometry
        wound = _wound(true_g, s.start_pose) + errors
        assert np.allclose(setup.physics.rest_lengths, wound, atol=1e-15)
        believed = _wound(setup.nominal.geometry, s.start_pose)
        assert np.allclose(setup.sensors.encoder_lengths, believed, atol=1e-15)
        T_pred, _ = _equilibrium(true_g, wound, s.start_pose)
        dp, dtheta = se3.pose_distance(T_pred, setup.physics.T_base_platform)
        assert dp < 1e-8 and dtheta < 1e-7
        assert se3.pose_distance(s.start_pose, setup.physics.T_base_platform)[0] > 1e-4
    finally:
        setup.sensors.close()
