"""Pure-math tests of cdpr_twin.math.kinematics and cdpr_twin.math.statics on ACROBOT's geometry.

The geometry is built directly from the paper's numbers (no MuJoCo), and every result is
checked against an independent truth: finite differences, the straight-cable limit, circle
geometry, hand values, and the static equilibrium itself.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from conftest import A_BASE, B_PLATFORM
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.linalg import null_space

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import (
    anchor_points_base,
    cable_lengths,
    cable_vectors,
    elastic_elongation,
    gravity_wrench,
    jacobian,
    pulley_state,
    rest_lengths,
)
from cdpr_twin.math.se3 import pose_from_vector, se3_exp, so3_exp, transform
from cdpr_twin.math.statics import InfeasibleTensionError, tension_distribution

PULLEY_RADIUS = 0.0045
ES = 111e9 * math.pi * 0.001**2  # E = 111 GPa, S = π (1 mm)²
MASS = 3.5

GEOM = CdprGeometry(
    a_base=A_BASE,
    b_platform=B_PLATFORM,
    pulley_radius=PULLEY_RADIUS,
    es=ES,
    mass=MASS,
    com_platform=np.zeros(3),
)

PAPER_POSES = {
    "p0": [0.112, -0.032, 0.301, -12.0, -10.0, 0.0],
    "p1": [0.284, -0.197, 0.08, 0.0, 0.0, 0.0],
    "p2": [0.284, -0.197, 0.25, 0.0, 0.0, 0.0],
}

N_EXAMPLES = 100
MODELS = ("straight", "pulley")


def with_radius(r: float) -> CdprGeometry:
    return dataclasses.replace(GEOM, pulley_radius=r)


@st.composite
def workspace_poses(draw: st.DrawFn) -> np.ndarray:
    """Platform poses in x, y ∈ [−0.25, 0.3], z ∈ [0.08, 0.4] m, rotations within ±15°."""

    def f(lo: float, hi: float) -> float:
        return draw(st.floats(lo, hi, allow_nan=False, allow_infinity=False))

    p = [f(-0.25, 0.3), f(-0.25, 0.3), f(0.08, 0.4), f(-15, 15), f(-15, 15), f(-15, 15)]
    return pose_from_vector(p)


# ---------------------------------------------------------------------------- geometry


def test_geometry_matches_acrobot_numbers() -> None:
    assert GEOM.n_cables == 8
    assert ES == pytest.approx(348716.8, abs=0.1)  # the model file's cable_es
    np.testing.assert_array_equal(GEOM.pulley_radius, np.full(8, PULLEY_RADIUS))
    np.testing.assert_array_equal(GEOM.gravity, [0.0, 0.0, -9.81])


def test_anchor_points_base() -> None:
    T = pose_from_vector([0.1, -0.2, 0.3, 0.0, 0.0, 90.0])
    b = np.array(B_PLATFORM)
    expected = np.column_stack([-b[:, 1], b[:, 0], b[:, 2]]) + np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(anchor_points_base(GEOM, T), expected, atol=1e-15)


def test_straight_lengths_hand_case() -> None:
    T = transform(np.eye(3), [0.0, 0.0, 0.3])
    b_base = np.array(B_PLATFORM) + np.array([0.0, 0.0, 0.3])
    expected = np.linalg.norm(b_base - np.array(A_BASE), axis=1)
    np.testing.assert_allclose(cable_lengths(GEOM, T, "straight"), expected, atol=1e-15)


# ---------------------------------------------------------------------------- Jacobians


def _moved_platform(T: np.ndarray, twist: np.ndarray, h: float) -> np.ndarray:
    """Platform-frame twist over h: T ← T · exp(h ξ)."""
    return T @ se3_exp(h * twist)


def _moved_base(T: np.ndarray, twist: np.ndarray, h: float) -> np.ndarray:
    """Base-frame twist of the platform origin over h: R ← exp(h ω) R, t ← t + h v."""
    return transform(so3_exp(h * twist[3:]) @ T[:3, :3], T[:3, 3] + h * twist[:3])


MOVES = {"platform": _moved_platform, "base": _moved_base}


def numerical_jacobian(T: np.ndarray, frame: str, model: str, h: float = 1e-5) -> np.ndarray:
    move = MOVES[frame]
    cols = []
    for j in range(6):
        xi = np.zeros(6)
        xi[j] = 1.0
        lp = cable_lengths(GEOM, move(T, xi, h), model)
        lm = cable_lengths(GEOM, move(T, xi, -h), model)
        cols.append((lp - lm) / (2.0 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("frame", ["platform", "base"])
@pytest.mark.parametrize("model", MODELS)
@given(T=workspace_poses())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_jacobian_matches_finite_differences(T: np.ndarray, frame: str, model: str) -> None:
    A = jacobian(GEOM, T, frame, model)
    assert A.shape == (8, 6)
    A_num = numerical_jacobian(T, frame, model)
    scale = np.abs(A_num).max()
    np.testing.assert_allclose(A, A_num, rtol=0, atol=1e-7 * scale)


@pytest.mark.parametrize("model", MODELS)
@given(T=workspace_poses())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_platform_and_base_jacobians_agree(T: np.ndarray, model: str) -> None:
    # The base twist of the origin is [R v_p, R ω_p]: A_p = A_b · blockdiag(R, R).
    R = T[:3, :3]
    blk = np.zeros((6, 6))
    blk[:3, :3] = blk[3:, 3:] = R
    np.testing.assert_allclose(
        jacobian(GEOM, T, "platform", model), jacobian(GEOM, T, "base", model) @ blk, atol=1e-14
    )


def test_jacobian_rejects_unknown_frame_and_model() -> None:
    T = pose_from_vector(PAPER_POSES["p0"])
    with pytest.raises(ValueError, match="frame"):
        jacobian(GEOM, T, "world")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cable model"):
        cable_lengths(GEOM, T, "catenary")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- pulleys


def _drop_angle(T: np.ndarray) -> np.ndarray:
    """Angle δ_i of the straight segment A_i → B_i below the horizontal [rad]."""
    lv = anchor_points_base(GEOM, T) - GEOM.a_base
    return np.arctan2(-lv[:, 2], np.hypot(lv[:, 0], lv[:, 1]))


@given(T=workspace_poses())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pulley_with_zero_radius_is_straight(T: np.ndarray) -> None:
    g0 = with_radius(0.0)
    l_s, u_s = cable_vectors(g0, T, "straight")
    l_p, u_p = cable_vectors(g0, T, "pulley")
    np.testing.assert_allclose(l_p, l_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(u_p, u_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(pulley_state(g0, T).wrap_length, 0.0, atol=0)


@given(T=workspace_poses())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pulley_length_exceeds_straight_by_order_radius(T: np.ndarray) -> None:
    l_s = cable_lengths(GEOM, T, "straight")
    diff = cable_lengths(GEOM, T, "pulley") - l_s
    assert np.all(diff > 0.0)
    assert np.all(diff < math.pi * PULLEY_RADIUS)  # the wrap is at most half the sheave
    # First order in r_p: the cable is shifted by r_p along x_i and wraps π/2 − δ on the sheave,
    # so l_pulley − l_straight = r_p (π/2 − δ − cos δ) + O(r_p² / l).
    delta = _drop_angle(T)
    first_order = math.pi / 2 - delta - np.cos(delta)
    for r in (1e-4, 1e-5):
        g = with_radius(r)
        d = cable_lengths(g, T, "pulley") - cable_lengths(g, T, "straight")
        assert np.all(d > 0.0)
        np.testing.assert_allclose(d / r, first_order, rtol=0, atol=r / l_s.min())


@given(T=workspace_poses())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pulley_tangent_point_geometry(T: np.ndarray) -> None:
    ps = pulley_state(GEOM, T)
    b = anchor_points_base(GEOM, T)
    a = GEOM.a_base
    r = PULLEY_RADIUS
    x_i = np.column_stack([np.cos(ps.phi), np.sin(ps.phi), np.zeros(8)])
    y_i = np.column_stack([-np.sin(ps.phi), np.cos(ps.phi), np.zeros(8)])
    c = ps.tangent - ps.center
    # the swivel points the pulley plane at B_i, the sheave centre is r_p out along x_i
    np.testing.assert_allclose(np.einsum("ij,ij->i", b - a, y_i), 0.0, atol=1e-15)
    np.testing.assert_allclose(ps.center, a + r * x_i, atol=1e-15)
    # A' is on the sheave circle, in the pulley plane, and the free segment is tangent there
    np.testing.assert_allclose(np.linalg.norm(c, axis=1), r, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", c, y_i), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.einsum("ij,ij->i", c, ps.u), 0.0, atol=1e-12 * r)
    np.testing.assert_allclose(np.linalg.norm(ps.u, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(ps.free_length, np.linalg.norm(b - ps.tangent, axis=1), rtol=1e-13)
    # the cable leaves A' below the sheave centre, toward B (below)
    assert np.all(c[:, 2] < 0.0)
    # wrap: the arc from A_i (A − P = −r x_i) down under the sheave to A', in the plane's
    # (x_i, z) coordinates travelled counter-clockwise from angle π
    ang = np.arctan2(c[:, 2], np.einsum("ij,ij->i", c, x_i)) % (2 * math.pi)
    np.testing.assert_allclose(ps.wrap_length, r * (ang - math.pi), rtol=1e-12)


# (swivel yaw φ [deg], drop angle δ of the free segment below the horizontal [deg], free
# length [m]) of eight hand-built cables, one per exit point A_i
PULLEY_HAND_CASES = [
    (0.0, 0.0, 1.0),
    (90.0, 45.0, 1.0),
    (180.0, 30.0, 0.7),
    (-45.0, 60.0, 1.25),
    (135.0, 15.0, 0.4),
    (-120.0, 75.0, 0.9),
    (20.0, 85.0, 1.1),
    (-170.0, 5.0, 0.6),
]


def test_pulley_lengths_hand_built_in_the_swivel_plane() -> None:
    """Plane geometry, built forward from the answer: in the pulley plane (x_i horizontal
    toward B_i, z up) the sheave centre is P = A + r x_i and the cable comes down the swivel
    axis onto the sheave at A (P's far side). It wraps under the sheave and leaves it at A'
    going down at δ below the horizontal along d = cos δ x_i − sin δ z; the radius P → A' is
    perpendicular to d on the lower side: A' = P − r (sin δ x_i + cos δ z). So the wrap is
    π/2 − δ (a quarter turn from A to the sheave's bottom for a horizontal cable, none for a
    vertical one) and B = A' + L d. Expect length L + r (π/2 − δ), free length L, and
    |B − P| = √(L² + r²) (tangent length √(d² − r²) from the sheave centre)."""
    r = PULLEY_RADIUS
    a = np.array(A_BASE)
    phi = np.deg2rad([c[0] for c in PULLEY_HAND_CASES])
    delta = np.deg2rad([c[1] for c in PULLEY_HAND_CASES])
    free = np.array([c[2] for c in PULLEY_HAND_CASES])
    x_i = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(8)])
    z = np.array([0.0, 0.0, 1.0])
    centre = a + r * x_i
    tangent = centre - r * (np.sin(delta)[:, None] * x_i + np.cos(delta)[:, None] * z)
    d = np.cos(delta)[:, None] * x_i - np.sin(delta)[:, None] * z
    b = tangent + free[:, None] * d
    g = dataclasses.replace(GEOM, b_platform=b)  # platform at the base origin: B in F_b
    ps = pulley_state(g, np.eye(4))
    np.testing.assert_allclose(ps.phi, phi, atol=1e-14)
    np.testing.assert_allclose(ps.center, centre, atol=1e-15)
    np.testing.assert_allclose(ps.tangent, tangent, atol=1e-15)
    np.testing.assert_allclose(ps.u, d, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(b - centre, axis=1), np.hypot(free, r), rtol=1e-15)
    np.testing.assert_allclose(ps.free_length, free, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ps.wrap_length, r * (math.pi / 2 - delta), rtol=0, atol=1e-15)
    expected = free + r * (math.pi / 2 - delta)
    np.testing.assert_allclose(cable_lengths(g, np.eye(4), "pulley"), expected, rtol=0, atol=2e-15)
    # cable 2 by hand: 1 m leaving at 45°, an eighth of a turn of the 4.5 mm sheave
    assert cable_lengths(g, np.eye(4), "pulley")[1] == pytest.approx(1.0035342917352885, abs=1e-15)


# ---------------------------------------------------------------------------- elasticity


def test_elastic_elongation_hand_case() -> None:
    lengths = np.array([1.0, 2.0, 0.5])
    tensions = np.array([10.0, 20.0, 4.0])
    es = np.array([1e5, 2e5, 4e5])
    np.testing.assert_allclose(
        elastic_elongation(lengths, tensions, es), [1e-4, 2e-4, 5e-6], rtol=1e-15
    )
    np.testing.assert_allclose(
        elastic_elongation(lengths, tensions, es, tensions0=np.array([2.0, 4.0, 4.0])),
        [8e-5, 1.6e-4, 0.0],
        rtol=1e-15,
        atol=0,
    )
    np.testing.assert_allclose(
        elastic_elongation(lengths, tensions, es, tensions0=10.0), [0.0, 1e-4, -7.5e-6], rtol=1e-15
    )


# ACROBOT's cable: E = 111 GPa, Ø 2 mm, E·S = 111e9 · π · (1 mm)² = 348 716.78 N, rounded as in
# the model file. Tensions picked as round strains τ/E·S; rest lengths and stretches worked out
# by hand (exact decimals): L = l0 (1 + τ/E·S) ⇒ l0 = L / (1 + τ/E·S), δl = l0 τ/E·S.
ES_FILE = 348716.8
ELASTIC_HAND_CASES = [
    # (stretched L [m], τ [N], rest l0 [m], stretch L − l0 [m])
    (1.2, 34.87168, 1.199880011998800, 1.199880011998800e-4),  # strain 1e-4: 1.2 / 1.0001
    (0.9, 69.74336, 0.8998200359928014, 1.799640071985603e-4),  # 2e-4: 0.9 / 1.0002
    (0.3, 6.974336, 0.2999940001199976, 5.999880002399952e-6),  # 2e-5: 0.3 / 1.00002
]


@pytest.mark.parametrize(("L", "tau", "l0", "stretch"), ELASTIC_HAND_CASES)
def test_rest_length_and_elongation_hand_case_acrobot_cable(
    L: float, tau: float, l0: float, stretch: float
) -> None:
    # the twin's cable law τ = E·S/l0 (L − l0) inverted (its rest lengths at reset) and eq. 14
    # with the unstretched length as l_i. The tolerances separate the exact inverse from its
    # first-order form L (1 − τ/E·S), off by L (τ/E·S)² = 1.2e-8 m to 1.2e-10 m here.
    es = np.array([ES_FILE])
    np.testing.assert_allclose(rest_lengths(np.array([L]), np.array([tau]), es), [l0], rtol=1e-14)
    np.testing.assert_allclose(
        elastic_elongation(np.array([l0]), np.array([tau]), es), [stretch], rtol=1e-13
    )
    assert l0 + stretch == pytest.approx(L, abs=1e-15)  # the hand values are consistent


@given(
    st.floats(0.3, 2.0),
    st.floats(0.0, 2e-4),
    st.floats(1e4, 1e6),
)
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_elastic_elongation_round_trip(l0: float, stretch: float, es: float) -> None:
    L = l0 + stretch
    tau = es / l0 * (L - l0)
    out = l0 + elastic_elongation(np.array([l0]), np.array([tau]), np.array([es]))
    np.testing.assert_allclose(out, [L], rtol=0, atol=4e-16)


# ---------------------------------------------------------------------------- statics


@pytest.mark.parametrize("name", sorted(PAPER_POSES))
def test_tension_distribution_holds_platform(name: str) -> None:
    T = pose_from_vector(PAPER_POSES[name])
    tau = tension_distribution(GEOM, T, tau_min=2.0, tau_max=75.0)
    assert tau.shape == (8,)
    assert np.all(tau >= 2.0 - 1e-9) and np.all(tau <= 75.0 + 1e-9), tau
    A = jacobian(GEOM, T, "base", "pulley")
    np.testing.assert_allclose(A.T @ tau, gravity_wrench(GEOM, T), rtol=0, atol=1e-9)
    # the cables pull up: the vertical force they exert on the platform (−Aᵀτ) carries m g
    assert (-A.T @ tau)[2] == pytest.approx(MASS * 9.81, rel=1e-12)


def min_norm_tensions_reference(W: np.ndarray, rhs: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Exact minimum-norm τ with W τ = rhs, lo ≤ τ ≤ hi, for a 2-D null space (8 cables, rank 6).

    τ = τ_p + N λ with τ_p ⟂ null(W), so ‖τ‖² = ‖τ_p‖² + ‖λ‖²: the answer is the point of the
    feasible polygon in λ nearest the origin, which is the origin, the foot of the perpendicular
    on one edge line, or a vertex. Enumerate them all (active-set enumeration, no optimiser).
    """
    tau_p = np.linalg.lstsq(W, rhs, rcond=None)[0]
    N = null_space(W)
    assert N.shape[1] == 2
    # half-planes n·λ ≥ c
    rows = [(N[i], lo - tau_p[i]) for i in range(len(tau_p))]
    rows += [(-N[i], tau_p[i] - hi) for i in range(len(tau_p))]
    candidates = [np.zeros(2)]
    candidates += [c * n / (n @ n) for n, c in rows]
    for (n1, c1), (n2, c2) in itertools.combinations(rows, 2):
        M = np.array([n1, n2])
        if abs(np.linalg.det(M)) > 1e-12:
            candidates.append(np.linalg.solve(M, [c1, c2]))

    def feasible(lam: np.ndarray) -> bool:
        tau = tau_p + N @ lam
        return bool(np.all(tau >= lo - 1e-9) and np.all(tau <= hi + 1e-9))

    return tau_p + N @ min(filter(feasible, candidates), key=lambda lam: float(lam @ lam))


# Poses at which SLSQP stops with "Positive directional derivative for linesearch" (status 8)
# at the optimum; found by random search over the workspace box (about 1 pose in 700).
SLSQP_STATUS8_POSES = [
    [
        0.260083160743508,
        0.28235940445855556,
        0.08470601758891817,
        10.909202707367271,
        14.435851201990328,
        13.716305388328905,
    ],
    [
        0.25808931472891883,
        0.19844663881982327,
        0.3396015886842293,
        11.930733452384299,
        -13.182711355291685,
        -7.583396359038424,
    ],
    [
        0.28231165824611215,
        0.2682082321352982,
        0.26428328410606333,
        8.7162816004362,
        -6.109004016026962,
        1.7374694951631575,
    ],
]


def _check_min_norm(T: np.ndarray) -> None:
    tau = tension_distribution(GEOM, T, tau_min=2.0, tau_max=75.0)
    W = jacobian(GEOM, T, "base", "pulley").T
    expected = min_norm_tensions_reference(W, gravity_wrench(GEOM, T), 2.0, 75.0)
    assert np.linalg.norm(tau) <= np.linalg.norm(expected) + 1e-9, (tau, expected)
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    "p", [*PAPER_POSES.values(), *SLSQP_STATUS8_POSES], ids=[*PAPER_POSES, "r1", "r2", "r3"]
)
def test_tension_distribution_is_minimum_norm(p: list[float]) -> None:
    _check_min_norm(pose_from_vector(p))


@given(T=workspace_poses())
@settings(max_examples=50, deadline=None)
def test_tension_distribution_is_minimum_norm_over_workspace(T: np.ndarray) -> None:
    try:
        tension_distribution(GEOM, T)
    except InfeasibleTensionError:
        assume(False)
    _check_min_norm(T)


def test_gravity_wrench_hand_case() -> None:
    g = dataclasses.replace(GEOM, com_platform=np.array([0.01, 0.0, -0.02]))
    T = pose_from_vector([0.1, 0.2, 0.3, 0.0, 0.0, 90.0])
    f = np.array([0.0, 0.0, -MASS * 9.81])
    c = np.array([0.0, 0.01, -0.02])  # com rotated by 90° about z
    np.testing.assert_allclose(
        gravity_wrench(g, T), np.concatenate([f, np.cross(c, f)]), rtol=1e-15, atol=1e-15
    )


def test_tension_distribution_infeasible_pose() -> None:
    T = transform(np.eye(3), [0.55, 0.55, 0.1])
    with pytest.raises(InfeasibleTensionError, match="no tension distribution"):
        tension_distribution(GEOM, T)
    assert issubclass(InfeasibleTensionError, ValueError)


@pytest.mark.parametrize(("tau_min", "tau_max"), [(80.0, 75.0), (10.0, 10.0), (-1.0, 75.0)])
def test_tension_distribution_bad_bounds(tau_min: float, tau_max: float) -> None:
    T = pose_from_vector(PAPER_POSES["p0"])
    with pytest.raises(ValueError, match="tau_min"):
        tension_distribution(GEOM, T, tau_min=tau_min, tau_max=tau_max)
