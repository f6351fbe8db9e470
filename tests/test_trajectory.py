"""Open-loop trajectory (eq. 26-30) against its closed form and its own integral."""

import numpy as np
from conftest import paper_pose

from cdpr_twin import kinematics as kin
from cdpr_twin import se3
from cdpr_twin.controllers import make_controller
from cdpr_twin.controllers.open_loop import quintic
from cdpr_twin.estimators.base import PoseEstimate


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


def test_planned_poses_and_twists_match_the_closed_form(twin):
    c = _controller(twin)
    T0, T1 = paper_pose("p0"), paper_pose("p1")
    theta_u = se3.so3_log(T0[:3, :3].T @ T1[:3, :3])
    for t in np.linspace(0, 10, 41):
        s, ds = quintic(t / 10)
        R = T0[:3, :3] @ se3.so3_exp(theta_u * s)
        expected = se3.transform(R, T0[:3, 3] + (T1[:3, 3] - T0[:3, 3]) * s)
        np.testing.assert_allclose(c.planned_pose(t), expected, atol=1e-12)
        twist = c.planned_twist_base(t)
        np.testing.assert_allclose(twist[:3], (T1[:3, 3] - T0[:3, 3]) * ds / 10, atol=1e-12)
        np.testing.assert_allclose(twist[3:], T0[:3, :3] @ theta_u * ds / 10, atol=1e-12)
    np.testing.assert_allclose(c.planned_pose(10.0), T1, atol=1e-12)
    np.testing.assert_allclose(c.planned_pose(25.0), T0, atol=1e-12)


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
