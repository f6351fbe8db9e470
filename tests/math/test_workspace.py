"""Wrench-feasible workspace: an analytic case, ACROBOT's paper waypoints, scenario validation.

Analytic case: a point-mass platform (every anchor at the centre of mass) hung from four top
corners (±a, ±a, H), two cables per corner. With τ ∈ [0, ∞) it is feasible exactly below the
exits' square (|x|, |y| < a). With τ ≤ τ_max, on the centre line all eight cables share the
weight equally at best, so it is feasible up to z* = H − √2·a·k/√(1−k²), k = m g / (8 τ_max).
"""

import math

import numpy as np
import pytest
from conftest import PAPER_POSES

from cdpr_twin import DEFAULT_SCENE, MODELS_DIR
from cdpr_twin.math import se3
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.workspace import check_waypoints, geometry_of, is_feasible, sample_workspace
from cdpr_twin.robot.description import load_robot
from cdpr_twin.sim import Twin, build_model, read_geometry

A, H, MASS = 0.5, 1.0, 2.0


def point_mass(tension_max: float) -> CdprGeometry:
    corners = [(sx * A, sy * A, H) for sx in (-1, 1) for sy in (-1, 1)]
    return CdprGeometry(
        a_base=[c for c in corners for _ in range(2)],
        b_platform=np.zeros((8, 3)),
        pulley_radius=0.0,
        es=1e5,
        mass=MASS,
        com_platform=np.zeros(3),
        frame_min=[-0.9, -0.9, 0.0],
        frame_max=[0.9, 0.9, 2.0],
        tension_min=0.0,
        tension_max=tension_max,
    )


def test_unbounded_tensions_feasible_exactly_below_the_exit_square():
    ws = sample_workspace(point_mass(math.inf), spacing=0.15)
    X, Y, _ = np.meshgrid(ws.xs, ws.ys, ws.zs, indexing="ij")
    below = (np.abs(X) < A) & (np.abs(Y) < A)
    assert ws.inside.all()
    np.testing.assert_array_equal(ws.feasible, below)  # grid points avoid the boundary |x| = a
    assert 0 < ws.feasible.sum() < ws.feasible.size


@pytest.mark.parametrize("tension_max", [3.0, 10.0])
def test_tension_limit_caps_the_height_as_the_closed_form_says(tension_max):
    geom = point_mass(tension_max)
    k = MASS * 9.81 / (8 * tension_max)
    z_star = H - math.sqrt(2) * A * k / math.sqrt(1 - k * k)
    for dz, expected in ((-1e-4, True), (1e-4, False)):
        T = se3.transform(np.eye(3), [0.0, 0.0, z_star + dz])
        assert is_feasible(geom, T) is expected, (z_star, dz)


def test_acrobot_paper_waypoints_are_feasible_and_the_twin_holds_a_sampled_pose():
    geom = read_geometry(build_model(DEFAULT_SCENE))
    assert (geom.tension_min, geom.tension_max) == (2.0, 75.0)  # from the description
    described = geometry_of(load_robot(MODELS_DIR / "acrobot" / "robot.toml"))
    poses = [se3.pose_from_vector(PAPER_POSES[k]) for k in ("p0", "p1", "p2")]
    check_waypoints(geom, poses)  # raises if one is not
    assert all(is_feasible(described, T) for T in poses)
    ws = sample_workspace(geom, spacing=0.2)
    assert ws.feasible.any() and not ws.feasible[ws.inside].all()
    # at a sampled feasible pose MuJoCo's physics holds the platform still, tensions in range
    pts = ws.points()
    T = se3.transform(np.eye(3), pts[np.argmax(pts[:, 2])])  # the highest feasible point
    with Twin(camera=False, tension_noise_std=0.0) as twin:
        twin.reset(T)
        twin.advance(0.5, np.zeros(8))
        dt, _ = se3.pose_distance(twin.physics.T_base_platform, T)
        tau = twin.physics.tensions
    assert dt < 1e-5
    assert np.all(tau > 2.0 - 0.05) and np.all(tau < 75.0 + 0.05)


def test_infeasible_pose_inside_the_frame_is_refused_with_the_limits():
    geom = read_geometry(build_model(DEFAULT_SCENE))
    T = se3.pose_from_vector([0.45, -0.45, 1.0, 0, 0, 0])
    geom.check_pose_inside(T)  # inside the frame …
    with pytest.raises(ValueError, match=r"waypoints\[0\].*wrench-feasible.*2 N ≤ τ ≤ 75 N"):
        check_waypoints(geom, [T])  # … but not wrench-feasible


def test_a_scenario_waypoint_outside_the_wrench_feasible_workspace_is_a_one_line_error(
    tmp_path, capsys
):
    from cdpr_twin.cli import main

    text = (MODELS_DIR.parent / "scenarios" / "paper_open_loop.toml").read_text()
    old = "[0.284, -0.197, 0.25, 0, 0, 0]"
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(
        text.replace(old, "[0.45, -0.45, 1.0, 0, 0, 0]", 1).replace(
            "../models/acrobot/scene.xml", str(DEFAULT_SCENE)
        )
    )
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-camera"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "controller.waypoints[1]" in err and "wrench-feasible" in err
    assert str(path) in err and not out.exists()


def test_a_vanishing_workspace_spacing_is_an_error_without_warnings():
    import warnings

    from cdpr_twin.math.workspace import spacing_problem
    from cdpr_twin.sim import Twin

    geom = Twin(camera=False).nominal_geometry
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert "gives inf grid points" in spacing_problem(geom, 1e-300)
