"""The 4-DoF gauge fit of self-calibration: exact on its own motions, blind to tilt."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from cdpr_twin.study.calibration_gauge import fit_gauge, fit_rigid


def _points(rng) -> np.ndarray:
    return rng.uniform(-0.6, 0.6, size=(8, 3))


def test_gauge_fit_removes_a_yaw_and_translation_exactly():
    rng = np.random.default_rng(1)
    Q = _points(rng)
    R = Rotation.from_euler("z", 0.3).as_matrix()
    P = (Q - [0.01, -0.02, 0.005]) @ R  # Q moved by a 4-DoF motion: Rᵀ(Q − t)
    yaw, _, moved = fit_gauge(P, Q)
    assert yaw == pytest.approx(0.3, abs=1e-12)
    np.testing.assert_allclose(moved, Q, atol=1e-12)


def test_gauge_fit_is_the_least_squares_optimum():
    # an independent optimiser over (yaw, t) finds the same residual as the closed form
    rng = np.random.default_rng(2)
    Q = _points(rng)
    P = Rotation.from_euler("xyz", [0.01, -0.02, 0.2]).apply(Q) + rng.normal(0, 1e-3, (8, 3))

    def residual(x):
        return (Rotation.from_euler("z", x[0]).apply(P) + x[1:] - Q).ravel()

    best = least_squares(residual, np.zeros(4), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    _, _, moved = fit_gauge(P, Q)
    assert np.sum((moved - Q) ** 2) == pytest.approx(2 * best.cost, rel=1e-9)


def test_a_tilt_stays_in_the_gauge_error_not_in_the_rigid_one():
    rng = np.random.default_rng(3)
    Q = _points(rng)
    P = Rotation.from_euler("x", np.radians(0.5)).apply(Q)  # tilt: seen by gravity
    _, _, moved4 = fit_gauge(P, Q)
    moved6 = fit_rigid(P, Q)
    assert np.median(np.linalg.norm(moved6 - Q, axis=1)) < 1e-12
    # a 0.5° tilt of points up to 0.6 m from the centre moves them by mm: not removed
    assert np.median(np.linalg.norm(moved4 - Q, axis=1)) > 1e-3
