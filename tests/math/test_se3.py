"""Tests of cdpr_twin.math.se3 against independent truths (hand values, scipy, matrix
exponential)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from cdpr_twin.math.se3 import (
    adjoint,
    euler_xyz_from_matrix,
    inverse,
    matrix_from_euler_xyz,
    matrix_from_quat_wxyz,
    pose_distance,
    pose_from_vector,
    quat_wxyz_from_matrix,
    rot_x,
    rot_y,
    rot_z,
    se3_exp,
    se3_log,
    skew,
    so3_exp,
    so3_log,
    transform,
    vector_from_pose,
)

N_EXAMPLES = 150
ANGLE_MAX = math.pi - 1e-6

# ---------------------------------------------------------------------------- strategies


def _finite(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def unit_vectors(draw: st.DrawFn) -> np.ndarray:
    v = np.array(draw(st.tuples(_finite(-1, 1), _finite(-1, 1), _finite(-1, 1))))
    n = np.linalg.norm(v)
    if n < 1e-3:
        return np.array([0.0, 0.0, 1.0])
    return v / n


# Angles on both sides of the switches between Taylor series and closed forms (θ = 1e-4 and
# θ = 1e-2 in the versions of se3.py seen so far), where cancellation in 1 − cos θ shows.
SMALL_ANGLES = [1e-5, 9.99e-5, 1.0001e-4, 1.01e-4, 2e-4, 1e-3, 9.99e-3, 1.0001e-2, 2e-2, 5e-2]

# θ over [0, π − 1e-6] with the delicate regions (0, tiny, the small-angle switches, just
# below π) drawn on purpose.
angles = st.one_of(
    _finite(0.0, ANGLE_MAX),
    _finite(1e-12, 1e-3),
    _finite(math.pi - 1e-3, ANGLE_MAX),
    _finite(1e-3, 3e-2),
    st.sampled_from([*SMALL_ANGLES, 0.0, 1e-10, 1e-8, 1e-6, math.pi / 2, ANGLE_MAX]),
)
vectors3 = st.tuples(_finite(-1, 1), _finite(-1, 1), _finite(-1, 1)).map(np.array)


@st.composite
def rotation_vectors(draw: st.DrawFn) -> np.ndarray:
    return draw(angles) * draw(unit_vectors())


@st.composite
def twists(draw: st.DrawFn) -> np.ndarray:
    return np.concatenate([draw(vectors3), draw(rotation_vectors())])


@st.composite
def rigid_transforms(draw: st.DrawFn) -> np.ndarray:
    return transform(so3_exp(draw(rotation_vectors())), draw(vectors3))


def hat(twist: np.ndarray) -> np.ndarray:
    """4×4 matrix of a ``[v, ω]`` twist, written independently of se3.py."""
    v, w = twist[:3], twist[3:]
    out = np.zeros((4, 4))
    out[:3, :3] = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
    out[:3, 3] = v
    return out


def assert_rotation(R: np.ndarray) -> None:
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


# ---------------------------------------------------------------------------- hand cases


def test_rot_xyz_quarter_turns() -> None:
    c = math.pi / 2
    np.testing.assert_allclose(rot_x(c), [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-15)
    np.testing.assert_allclose(rot_y(c), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(rot_z(c), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    ex, ey, ez = np.eye(3)
    np.testing.assert_allclose(rot_x(c) @ ey, ez, atol=1e-15)
    np.testing.assert_allclose(rot_y(c) @ ez, ex, atol=1e-15)
    np.testing.assert_allclose(rot_z(c) @ ex, ey, atol=1e-15)


def test_so3_exp_hand_cases() -> None:
    np.testing.assert_allclose(so3_exp([math.pi / 2, 0, 0]), rot_x(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(so3_exp([0, -0.3, 0]), rot_y(-0.3), atol=1e-15)
    np.testing.assert_allclose(so3_exp([0, 0, math.pi]), rot_z(math.pi), atol=1e-15)
    np.testing.assert_allclose(so3_exp(np.zeros(3)), np.eye(3), atol=0)


def test_so3_log_hand_cases() -> None:
    np.testing.assert_allclose(so3_log(np.eye(3)), np.zeros(3), atol=0)
    np.testing.assert_allclose(so3_log(rot_z(math.pi / 2)), [0, 0, math.pi / 2], atol=1e-15)
    w = so3_log(rot_x(math.pi))  # θ = π: the axis is defined up to sign
    np.testing.assert_allclose(np.abs(w), [math.pi, 0, 0], atol=1e-15)


@given(vectors3, vectors3)
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_skew_is_cross_product(v: np.ndarray, w: np.ndarray) -> None:
    np.testing.assert_allclose(skew(v) @ w, np.cross(v, w), atol=1e-15)
    np.testing.assert_array_equal(skew(v), -skew(v).T)


def test_adjoint_hand_case() -> None:
    R, t = rot_z(math.pi / 2), np.array([1.0, 2.0, 3.0])
    Ad = adjoint(transform(R, t))
    expected = np.zeros((6, 6))  # eq. 4: [[R, [t]× R], [0, R]], [t]× R column by column
    expected[:3, :3] = R
    expected[:3, 3:] = np.column_stack([np.cross(t, R[:, j]) for j in range(3)])
    expected[3:, 3:] = R
    np.testing.assert_allclose(Ad, expected, atol=1e-15)
    # A pure rotation about z in F_b, seen from F_a: ω' = R ez = ez, v' = t × ez = (2, −1, 0).
    np.testing.assert_allclose(Ad @ [0, 0, 0, 0, 0, 1], [2, -1, 0, 0, 0, 1], atol=1e-15)


def test_pose_from_vector_hand_case() -> None:
    T = pose_from_vector([0.1, -0.2, 0.3, 90, 0, 0])
    np.testing.assert_allclose(T[:3, :3], rot_x(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], [0.1, -0.2, 0.3], atol=0)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1], atol=0)


# ---------------------------------------------------------------------------- so(3)


@given(rotation_vectors())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_so3_log_inverts_so3_exp(theta_u: np.ndarray) -> None:
    R = so3_exp(theta_u)
    assert_rotation(R)
    np.testing.assert_allclose(so3_log(R), theta_u, rtol=0, atol=1e-12)
    np.testing.assert_allclose(so3_exp(so3_log(R)), R, rtol=0, atol=1e-14)


@given(rotation_vectors())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_so3_exp_matches_scipy(theta_u: np.ndarray) -> None:
    expected = Rotation.from_rotvec(theta_u).as_matrix()
    np.testing.assert_allclose(so3_exp(theta_u), expected, rtol=0, atol=1e-14)


@given(rotation_vectors())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_so3_exp_matches_matrix_exponential(theta_u: np.ndarray) -> None:
    np.testing.assert_allclose(so3_exp(theta_u), expm(skew(theta_u)), rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------- se(3)


@given(twists())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_se3_exp_matches_matrix_exponential(twist: np.ndarray) -> None:
    np.testing.assert_allclose(se3_exp(twist), expm(hat(twist)), rtol=0, atol=1e-12)


@given(twists())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_se3_log_inverts_se3_exp(twist: np.ndarray) -> None:
    T = se3_exp(twist)
    np.testing.assert_allclose(se3_log(T), twist, rtol=0, atol=1e-10)
    np.testing.assert_allclose(se3_exp(se3_log(T)), T, rtol=0, atol=1e-12)


@pytest.mark.parametrize("theta", SMALL_ANGLES)
def test_small_angle_accuracy(theta: float) -> None:
    # Below and above each switch to a Taylor series, exp and log must stay accurate to
    # round-off; a closed form such as d = (1 − θ sinθ / (2(1 − cosθ))) / θ² used too close to
    # θ = 0 loses ~1e-16/θ² of relative accuracy (the bug of se3.py before commit 8854549).
    w = theta * np.array([0.0, 0.6, 0.8])
    twist = np.concatenate([[0.3, -0.7, 0.9], w])
    T = expm(hat(twist))
    np.testing.assert_allclose(se3_exp(twist), T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(se3_log(T), twist, rtol=0, atol=1e-10)
    np.testing.assert_allclose(so3_exp(w), T[:3, :3], rtol=0, atol=1e-15)
    np.testing.assert_allclose(so3_log(T[:3, :3]), w, rtol=0, atol=1e-15)


@given(rigid_transforms(), twists())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_adjoint_conjugates_twists(T: np.ndarray, twist: np.ndarray) -> None:
    # T exp(ξ^) T⁻¹ = exp((Ad_T ξ)^)
    lhs = T @ expm(hat(twist)) @ np.linalg.inv(T)
    rhs = expm(hat(adjoint(T) @ twist))
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-11)
    # and the hat map is conjugated exactly: T ξ^ T⁻¹ = (Ad_T ξ)^
    np.testing.assert_allclose(
        T @ hat(twist) @ np.linalg.inv(T), hat(adjoint(T) @ twist), rtol=0, atol=1e-13
    )


@given(rigid_transforms())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_inverse(T: np.ndarray) -> None:
    np.testing.assert_allclose(inverse(T) @ T, np.eye(4), rtol=0, atol=1e-14)
    np.testing.assert_allclose(T @ inverse(T), np.eye(4), rtol=0, atol=1e-14)
    np.testing.assert_allclose(inverse(T), np.linalg.inv(T), rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.inv(adjoint(T)), adjoint(inverse(T)), atol=1e-12)


# ---------------------------------------------------------------------------- quaternions


@st.composite
def quaternions(draw: st.DrawFn) -> np.ndarray:
    q = np.array(draw(st.tuples(*[_finite(-1, 1)] * 4)))
    if np.linalg.norm(q) < 1e-3:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    return q * draw(_finite(0.1, 10.0))  # need not be normalised


def _same_quat(q1: np.ndarray, q2: np.ndarray, atol: float) -> bool:
    return min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max()) <= atol


@given(quaternions())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_matrix_from_quat_matches_scipy(q: np.ndarray) -> None:
    R = matrix_from_quat_wxyz(q)
    assert_rotation(R)
    expected = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # scipy: xyzw
    np.testing.assert_allclose(R, expected, rtol=0, atol=1e-14)


@given(quaternions())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_quat_round_trip(q: np.ndarray) -> None:
    qn = q / np.linalg.norm(q)
    out = quat_wxyz_from_matrix(matrix_from_quat_wxyz(q))
    assert np.linalg.norm(out) == pytest.approx(1.0, abs=1e-15)
    assert out[0] >= 0.0
    assert _same_quat(out, qn, 1e-13), (out, qn)


@given(rotation_vectors())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_quat_from_matrix_matches_scipy(theta_u: np.ndarray) -> None:
    R = Rotation.from_rotvec(theta_u)
    x, y, z, w = R.as_quat()
    out = quat_wxyz_from_matrix(R.as_matrix())
    assert _same_quat(out, np.array([w, x, y, z]), 1e-13), (out, R.as_quat())


def test_quat_hand_cases() -> None:
    np.testing.assert_allclose(quat_wxyz_from_matrix(np.eye(3)), [1, 0, 0, 0], atol=0)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quat_wxyz_from_matrix(rot_z(math.pi / 2)), [s, 0, 0, s], atol=1e-15)
    np.testing.assert_allclose(matrix_from_quat_wxyz([s, s, 0, 0]), rot_x(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(matrix_from_quat_wxyz([0, 0, 2, 0]), rot_y(math.pi), atol=1e-15)


# ---------------------------------------------------------------------------- Euler angles

degrees = _finite(-180.0, 180.0)


@given(st.tuples(degrees, degrees, degrees).map(np.array))
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_matrix_from_euler_xyz_matches_scipy_intrinsic(angles_deg: np.ndarray) -> None:
    expected = Rotation.from_euler("XYZ", angles_deg, degrees=True).as_matrix()
    np.testing.assert_allclose(
        matrix_from_euler_xyz(np.deg2rad(angles_deg)), expected, rtol=0, atol=1e-14
    )
    T = pose_from_vector(np.concatenate([[0.1, 0.2, 0.3], angles_deg]))
    np.testing.assert_allclose(T[:3, :3], expected, rtol=0, atol=1e-14)


@given(
    vectors3,
    _finite(-179.0, 179.0),
    _finite(-85.0, 85.0),  # away from gimbal lock (ry = ±90°)
    _finite(-179.0, 179.0),
)
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pose_vector_round_trip(t: np.ndarray, rx: float, ry: float, rz: float) -> None:
    p = np.concatenate([t, [rx, ry, rz]])
    T = pose_from_vector(p)
    np.testing.assert_allclose(vector_from_pose(T), p, rtol=0, atol=1e-9)
    scipy_angles = Rotation.from_matrix(T[:3, :3]).as_euler("XYZ", degrees=True)
    np.testing.assert_allclose(vector_from_pose(T)[3:], scipy_angles, rtol=0, atol=1e-9)


@pytest.mark.parametrize("ry", [90.0, -90.0])
def test_euler_gimbal_lock_reproduces_matrix(ry: float) -> None:
    R = matrix_from_euler_xyz(np.deg2rad([30.0, ry, 40.0]))
    angles = euler_xyz_from_matrix(R)
    assert angles[1] == pytest.approx(np.deg2rad(ry))
    np.testing.assert_allclose(matrix_from_euler_xyz(angles), R, atol=1e-14)


# ---------------------------------------------------------------------------- pose distance


@given(rigid_transforms(), rigid_transforms())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pose_distance_symmetric(Ta: np.ndarray, Tb: np.ndarray) -> None:
    dab, dba = pose_distance(Ta, Tb), pose_distance(Tb, Ta)
    assert dab[0] == pytest.approx(dba[0], abs=1e-15)
    assert dab[1] == pytest.approx(dba[1], abs=1e-12)
    assert dab[0] >= 0 and 0 <= dab[1] <= math.pi + 1e-12


@given(rigid_transforms(), vectors3, angles, unit_vectors())
@settings(max_examples=N_EXAMPLES, deadline=None)
def test_pose_distance_known_relative_motion(
    Ta: np.ndarray, dt: np.ndarray, theta: float, u: np.ndarray
) -> None:
    Tb = transform(Ta[:3, :3] @ so3_exp(theta * u), Ta[:3, 3] + dt)
    trans, rot = pose_distance(Ta, Tb)
    assert trans == pytest.approx(np.linalg.norm(dt), abs=1e-15)
    assert rot == pytest.approx(theta, abs=1e-12)
    # the rotation is in the body frame of Ta; in the base frame it is the same angle
    Tc = transform(so3_exp(theta * u) @ Ta[:3, :3], Ta[:3, 3])
    assert pose_distance(Ta, Tc)[1] == pytest.approx(theta, abs=1e-12)


def test_pose_distance_hand_case() -> None:
    Ta = pose_from_vector([0, 0, 0, 0, 0, 0])
    Tb = pose_from_vector([0.3, 0.4, 0, 0, 0, 30])
    trans, rot = pose_distance(Ta, Tb)
    assert trans == pytest.approx(0.5, abs=1e-15)
    assert rot == pytest.approx(math.radians(30), abs=1e-15)


# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "q", [np.zeros(4), np.full(4, np.nan), np.array([1.0, np.inf, 0.0, 0.0]), np.full(4, 1e-14)]
)
def test_matrix_from_quat_rejects_zero_or_nonfinite(q: np.ndarray) -> None:
    with pytest.raises(ValueError):
        matrix_from_quat_wxyz(q)


@pytest.mark.parametrize(
    "p",
    [
        [0.1, 0.2, 0.3, 0.0, 0.0],  # 5 numbers
        [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 0.0],  # 7 numbers
        [0.1, np.nan, 0.3, 0.0, 0.0, 0.0],
        [0.1, 0.2, 0.3, 0.0, np.inf, 0.0],
        [[0.1, 0.2, 0.3, 0.0, 0.0, 0.0]],  # (1, 6)
    ],
)
def test_pose_from_vector_rejects_bad_input(p: list) -> None:
    with pytest.raises(ValueError):
        pose_from_vector(np.array(p))
