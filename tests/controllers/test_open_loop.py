"""Open-loop trajectory (eq. 26-30) against its closed form and its own integral."""

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.controllers.open_loop import quintic
from cdpr_twin.estimators.base import PoseEstimate
from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.plugins import make_controller


def _controller(twin):
    c = make_controller(
        "open_loop",
        twin.nominal_geometry,
        waypoints=[paper_pose("p1"), paper_pose("p2"), paper_pose("p0")],
        durations=[10.0, 5.0, 10.0],
    )
    c.reset(paper_pose("p0"))
    return c


def test_quintic_boundary_conditions_and_closed_form():
    for tau in np.linspace(0, 1, 11):
        s, ds = quintic(tau)
        assert np.isclose(s, 10 * tau**3 - 15 * tau**4 + 6 * tau**5)
        assert np.isclose(ds, 30 * tau**2 - 60 * tau**3 + 30 * tau**4)
    # s(0) = ṡ(0) = 0, s(1) = 1, ṡ(1) = 0; s̈ = 0 at both ends (finite differences)
    assert quintic(0.0) == (0.0, 0.0) and quintic(1.0) == (1.0, 0.0)
    h = 1e-5
    for end in (0.0, 1.0 - 2 * h):
        assert abs(quintic(end + 2 * h)[1] - 2 * quintic(end + h)[1] + quintic(end)[1]) < 1e-8


def _angle_axis(R):
    """Rotation angle from the trace and unit axis from the skew part (no so3_log)."""
    w = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return np.arctan2(np.linalg.norm(w), 0.5 * (np.trace(R) - 1.0)), w / np.linalg.norm(w)


# quintic values by hand: s(τ) = 10τ³ − 15τ⁴ + 6τ⁵, s(1/4) = (160 − 60 + 6)/1024
S_QUARTER = 106 / 1024  # 0.103515625
DS_HALF = 30 / 16  # ds/dτ at τ = 1/2: 30 τ²(1 − τ)² = 1.875


def test_planned_trajectory_passes_the_waypoints_on_straight_quintic_segments(twin):
    """Independent properties of eq. 26-29 (none recomputes the controller's formula): the
    waypoints at the segment ends, at rest there, straight lines at the quintic's hand values,
    one fixed rotation axis with the angle on the same timing law as the position."""
    c = _controller(twin)
    p0, p1, p2 = paper_pose("p0"), paper_pose("p1"), paper_pose("p2")
    for t, T in ((0.0, p0), (10.0, p1), (15.0, p2), (25.0, p0), (30.0, p0)):
        np.testing.assert_allclose(c.planned_pose(t), T, atol=1e-15)
    for t in (0.0, 10.0, 15.0, 25.0, -1.0, 30.0):
        np.testing.assert_allclose(c.planned_twist_base(t), 0.0, atol=1e-15)
    # first segment p0 → p1 (translation and rotation): positions on the segment at the hand
    # fractions s(1/4), s(1/2) = 1/2, s(3/4) = 1 − s(1/4), and symmetric about the midpoint
    d = p1[:3, 3] - p0[:3, 3]
    angle_total, axis_total = _angle_axis(p0[:3, :3].T @ p1[:3, :3])
    assert np.rad2deg(angle_total) > 15.0  # p0 is tilted by (−12°, −10°), p1 is level
    for t, s in ((2.5, S_QUARTER), (5.0, 0.5), (7.5, 1.0 - S_QUARTER)):
        np.testing.assert_allclose(c.planned_pose(t)[:3, 3], p0[:3, 3] + s * d, atol=1e-15)
        np.testing.assert_allclose(
            c.planned_pose(t)[:3, 3] + c.planned_pose(10.0 - t)[:3, 3],
            p0[:3, 3] + p1[:3, 3],
            atol=1e-15,
        )
    for t in np.linspace(0.25, 9.75, 39):
        T = c.planned_pose(t)
        # on the straight line p0 → p1, the fraction travelled ...
        offset = T[:3, 3] - p0[:3, 3]
        np.testing.assert_allclose(np.cross(offset, d), 0.0, atol=1e-15)
        s = offset @ d / (d @ d)
        # ... equals the fraction of the rotation angle, about p0 → p1's fixed axis
        angle, axis = _angle_axis(p0[:3, :3].T @ T[:3, :3])
        np.testing.assert_allclose(axis, axis_total, atol=1e-12)
        assert angle == pytest.approx(s * angle_total, abs=1e-12)
    # peak speed at the midpoint: ṡ = (ds/dτ)/10 s with ds/dτ(1/2) = 1.875
    v = c.planned_twist_base(5.0)
    np.testing.assert_allclose(v[:3], DS_HALF * d / 10.0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(v[3:]), DS_HALF * angle_total / 10.0, rtol=1e-12)
    # second segment p1 → p2: a pure 17 cm climb at constant orientation
    for t, s in ((12.5, 0.5), (11.25, S_QUARTER)):
        T = c.planned_pose(t)
        np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-15)
        np.testing.assert_allclose(T[:3, 3], [0.284, -0.197, 0.08 + 0.17 * s], atol=1e-15)


def test_the_twist_integrates_to_the_planned_poses(twin):
    """Midpoint integration of the base-frame twist, and of the platform twist the controller
    commands, reproduce the planned trajectory (and the finite-difference derivative)."""
    c = _controller(twin)
    T = paper_pose("p0")
    dt = 0.001
    for k in range(25000):
        t = k * dt
        cmd = c.command(t, dt, PoseEstimate(t, T), None)
        T = T @ se3.se3_exp(cmd.twist_platform * dt)
        if k % 2500 == 2499:
            dist = se3.pose_distance(T, c.planned_pose(t + dt))
            assert dist[0] < 2e-7 and dist[1] < 2e-7
    # finite differences of the plan equal the planned base twist
    for t in (2.0, 12.5, 20.0):
        h = 1e-6
        Ta, Tb = c.planned_pose(t - h), c.planned_pose(t + h)
        v = (Tb[:3, 3] - Ta[:3, 3]) / (2 * h)
        w = se3.so3_log(Tb[:3, :3] @ Ta[:3, :3].T) / (2 * h)
        np.testing.assert_allclose(np.concatenate([v, w]), c.planned_twist_base(t), atol=1e-7)


def test_rates_are_the_jacobian_at_the_planned_midpoint(twin):
    c = _controller(twin)
    cmd = c.command(3.0, 0.04, PoseEstimate(3.0, np.eye(4)), None)
    A = kin.jacobian(twin.nominal_geometry, c.planned_pose(3.02), "base", "straight")
    np.testing.assert_allclose(cmd.cable_rates, A @ c.planned_twist_base(3.02), atol=1e-15)
