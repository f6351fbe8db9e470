"""How a calibration drives and reads the robot, and the solver's damping, against truth.

- tightening: the simulated robot's own cable tensions (physics, not the sensors) after it;
  its internal-force step, against the robot's own tension change and pose (it does not move
  the platform) and against the tension-space linear programs;
- the tour: a greedy nearest-neighbour order written out here, pose by pose;
- the damping: Rosenbrock's valley, whose minimum is known, from a start where Gauss–Newton's
  first step overshoots;
- the camera: a frame drawn once and reused equals a fresh renderer's draw of the same state.
"""

import math

import numpy as np
import pytest

from cdpr_twin.calibrate import drive
from cdpr_twin.calibrate.excitation import excitation_poses, tour
from cdpr_twin.calibrate.normal_equations import levenberg_marquardt
from cdpr_twin.scenario.loading import load_scenario


def _robot(s):
    from cdpr_twin.sim import Sensors, build_robot

    built = build_robot(
        s.model.file, s.truth, s.model.timestep, s.model.align_every, s.realism.winch
    )
    physics, nominal = built.physics, built.nominal
    sensors = Sensors(
        physics,
        nominal,
        s.sensors.tension_noise_std,
        s.seed,
        camera=False,
        realism=s.realism,
        robot_seed=s.truth.seed,
        period=s.model.control_period,
    )
    physics.reset(s.start_pose, settle_time=0.3)
    sensors.home(s.start_pose)
    return physics, nominal, sensors


def test_tightening_leaves_every_true_cable_taut_after_an_open_loop_move():
    s = load_scenario("paper_open_loop")  # robot 19: exit points 12 mm off the nominal ones
    physics, nominal, sensors = _robot(s)
    g, period = nominal.geometry, s.model.control_period
    poses = excitation_poses(
        g, nominal.T_base_tag, nominal.intrinsics, nominal.tag_size, 6, s.start_pose
    )
    rest, slack_before = np.zeros(physics.n_cables), 0
    here = s.start_pose
    for T in poses:
        drive.move(physics, g, here, T, period)
        physics.advance(0.4, rest)
        slack_before += int(np.sum(physics.tensions < 0.5))
        ticks = drive.tighten(physics, sensors, g, T)
        physics.advance(0.4, rest)
        assert ticks != 0  # it had to reel in (-1: a cable still just under 3 N at the timeout)
        # taut where the calibration reads (above 1 N): the platform settling after the last
        # tick unloads some (to 1.06 N at one of these poses), and the sensors are 0.24 N off
        assert np.all(physics.tensions > 1.0), physics.tensions
        here = T
    assert slack_before >= len(poses)  # the nominal model's lengths left cables slack


def test_an_internal_force_step_changes_the_tensions_without_moving_the_platform():
    # truth: the simulated robot's tensions and pose; the step is planned on the nominal model
    from scipy.linalg import null_space

    from cdpr_twin.math.kinematics import cable_lengths, jacobian
    from cdpr_twin.math.se3 import pose_distance
    from cdpr_twin.sim import build_robot

    s = load_scenario("paper_open_loop")  # robot 19: exit points 12 mm off the nominal ones
    built = build_robot(s.model.file, s.truth, s.model.timestep, s.model.align_every)
    physics, nominal = built.physics, built.nominal
    g, T, dt = nominal.geometry, s.start_pose, 0.02
    N = null_space(jacobian(g, T, "base", "pulley").T)
    k = g.es / cable_lengths(g, T, "pulley")

    def after(lengths):
        physics.reset(T, settle_time=0.5)
        tau0, P0 = physics.tensions.copy(), physics.T_base_platform
        physics.advance(dt, lengths / dt)
        physics.advance(0.5, np.zeros(physics.n_cables))
        return physics.tensions - tau0, pose_distance(P0, physics.T_base_platform)

    physics.reset(T, settle_time=0.5)
    change, _ = drive._internal_forces(N, physics.tensions.copy(), 4.0, g.tension_max)
    assert np.abs(change).max() > 0.3  # [N]: a step worth measuring
    got, moved = after(-change / k)
    assert np.linalg.norm(got - change) < 0.15 * np.linalg.norm(change), (got, change)
    one = np.zeros_like(change)  # the same length, all on the cable that moves most
    one[np.argmax(np.abs(change))] = -np.linalg.norm(change / k)
    _, moved_one = after(one)
    assert moved[0] < 1e-6 and moved[1] < 5e-6  # [m], [rad]
    assert moved[0] < 0.3 * moved_one[0] and moved[1] < 0.3 * moved_one[1]


def test_internal_forces_reach_the_least_total_tension_or_else_the_greatest_least_one():
    # truth: the tension-space linear programs of statics and the workspace's feasibility test
    from scipy.linalg import null_space
    from scipy.optimize import linprog

    from cdpr_twin.math.kinematics import gravity_wrench, jacobian
    from cdpr_twin.math.statics import tension_distribution
    from cdpr_twin.math.workspace import is_feasible
    from cdpr_twin.sim import build_robot

    s = load_scenario("paper_open_loop")
    g = build_robot(s.model.file).nominal.geometry
    T = s.start_pose
    W = jacobian(g, T, "base", "pulley").T
    N, tau = null_space(W), tension_distribution(g, T)
    change, best = drive._internal_forces(N, tau, 3.5, g.tension_max)
    np.testing.assert_allclose(W @ change, 0.0, atol=1e-9)  # the same wrench
    assert (tau + change).min() == pytest.approx(best) and best >= 3.5 - 1e-9
    least = linprog(
        np.ones(g.n_cables),
        A_eq=W,
        b_eq=gravity_wrench(g, T),
        bounds=[(3.5, g.tension_max)] * g.n_cables,
        method="highs",
    )
    assert (tau + change).sum() == pytest.approx(least.fun, abs=1e-6)
    change, best = drive._internal_forces(N, tau, 50.0, g.tension_max)  # out of reach
    assert (tau + change).min() == pytest.approx(best, abs=1e-9)
    assert is_feasible(g, T, tension_min=best - 1e-3)
    assert not is_feasible(g, T, tension_min=best + 1e-3)


def test_tightening_gives_up_at_its_timeout_and_says_so():
    s = load_scenario("paper_open_loop")
    physics, nominal, sensors = _robot(s)
    physics.disable_cable(0)  # a broken cable: no reeling makes it read
    assert drive.tighten(physics, sensors, nominal.geometry, s.start_pose, timeout=0.5) == -1
    assert physics.time == pytest.approx(0.5, abs=0.03)  # (time restarts at a reset)


def _greedy(poses, start):
    """Each next pose the nearest to the last: position + 0.2 m per radian of rotation."""
    left, out, here = list(range(len(poses))), [], start
    while left:
        costs = []
        for i in left:
            R = here[:3, :3].T @ poses[i][:3, :3]
            angle = math.acos(max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0))))
            costs.append(np.linalg.norm(poses[i][:3, 3] - here[:3, 3]) + 0.2 * angle)
        j = left.pop(int(np.argmin(costs)))
        out.append(j)
        here = poses[j]
    return out


def test_the_tour_visits_the_nearest_pose_next():
    from cdpr_twin.math.se3 import pose_from_vector

    rng = np.random.default_rng(7)
    poses = [
        pose_from_vector([*rng.uniform(-0.3, 0.3, 3), *rng.uniform(-12, 12, 3)]) for _ in range(60)
    ]
    start = pose_from_vector([0.0, 0.0, 0.3, 0, 0, 0])
    got = tour(poses, start)
    assert [next(i for i, p in enumerate(poses) if p is q) for q in got] == _greedy(poses, start)
    assert tour([], start) == []


@pytest.mark.parametrize("lam0", [1e-8, 1e-3, 1.0])
def test_levenberg_marquardt_finds_rosenbrocks_minimum_from_any_starting_damping(lam0):
    # r = (10 (y − x²), 1 − x): minimum 0 at (1, 1); from (−1.2, 1) the undamped step overshoots
    from scipy.sparse import csc_matrix

    def fun(x):
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def jac(x):
        return csc_matrix(np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])), 0

    res = levenberg_marquardt(fun, jac, np.array([-1.2, 1.0]), lam0=lam0, shrink=0.1)
    assert res.converged, res.message
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-8)


def test_a_frame_drawn_again_is_a_fresh_draw_of_the_same_state():
    from cdpr_twin.sim import build_robot
    from cdpr_twin.sim.camera import CameraRenderer

    s = load_scenario("paper_open_loop")
    physics = build_robot(s.model.file).physics
    physics.reset(s.start_pose, settle_time=0.3)
    d = physics.data
    state = (d.qpos.copy(), d.mocap_pos.copy(), d.mocap_quat.copy())
    moved = (state[0] + np.r_[1e-4, np.zeros(len(state[0]) - 1)], *state[1:])
    reused, fresh = CameraRenderer(physics.model), CameraRenderer(physics.model)
    try:
        first = reused.render_state(*state)
        again = reused.render_state(*state)  # the same scene: not drawn again
        np.testing.assert_array_equal(again, fresh.render_state(*state))
        assert again is not first  # a copy: the caller may write into it
        after = reused.render_state(*moved)  # 0.1 mm along x: drawn anew
        fresh2 = CameraRenderer(physics.model)
        try:
            np.testing.assert_array_equal(after, fresh2.render_state(*moved))
        finally:
            fresh2.close()
        assert np.any(after != first)
    finally:
        reused.close()
        fresh.close()


def test_a_rest_shorter_than_the_swing_would_read_a_moving_platform():
    # truth: the platform's own speed (physics) where the calibration starts reading
    from cdpr_twin.calibrate.acquire import SETTLE

    s = load_scenario("paper_open_loop")
    physics, nominal, _ = _robot(s)
    g, period = nominal.geometry, s.model.control_period
    T = excitation_poses(
        g, nominal.T_base_tag, nominal.intrinsics, nominal.tag_size, 1, s.start_pose
    )[0]
    drive.move(physics, g, s.start_pose, T, period)
    rest = np.zeros(physics.n_cables)
    speeds = []
    for _ in range(round(SETTLE / period)):
        physics.advance(period, rest)
        speeds.append(np.abs(physics.data.qvel[:3]).max())
    assert speeds[0] > 100 * speeds[-1]  # the move's swing, decayed
    assert speeds[-1] < 1e-5  # [m/s]: under 0.4 µm over the four frames read (0.16 s)
