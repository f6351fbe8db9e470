"""SO(3)/SE(3) functions: exp/log, adjoint, θu, quaternions, file poses, pose distance.

Quaternion conversions and the pose distance take one pose or any stack (leading axes), one
implementation each (jaxlie's style); one pose takes a bit-identical fast path in plain floats,
as the Newton kernels of :mod:`cdpr_twin.estimators.model_based` do (a test holds them to these).

Conventions: homogeneous transforms are 4×4 arrays named ``T_<to>_<from>``;
twists are ``[v, ω]`` (linear first); quaternions are ``quat_wxyz`` (scalar first, the MuJoCo
order); poses in files are ``[x, y, z, rx, ry, rz]`` in metres and degrees with
R = Rx(rx)·Ry(ry)·Rz(rz) (intrinsic XYZ). Everything here imports numpy only.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

_SMALL = 1e-8
_SERIES = 1e-4
"""Below this θ², coefficients with cancellation (1 − cos θ, θ − sin θ…) use Taylor series,
accurate there to round-off (the next term is below θ⁶/5e6)."""


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]×.

    Args:
        v: (3,) vector.

    Returns:
        (3, 3) matrix with ``skew(v) @ w == np.cross(v, w)``.
    """
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rot_x(angle: float) -> np.ndarray:
    """Rotation matrix about x by ``angle`` rad. Returns (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """Rotation matrix about y by ``angle`` rad. Returns (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """Rotation matrix about z by ``angle`` rad. Returns (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Homogeneous transform from rotation (3, 3) and translation (3,) [m]. Returns (4, 4)."""
    T = np.zeros((4, 4))
    T[:3, :3] = R
    T[:3, 3] = t
    T[3, 3] = 1.0
    return T


def check_rigid(T: np.ndarray, what: str = "pose", tol: float = 1e-6) -> np.ndarray:
    """Return ``T`` as a float (4, 4) array, or raise ``ValueError`` if it is not a rigid transform.

    Args:
        T: candidate transform.
        what: how to name it in the error message.
        tol: tolerance on ‖RᵀR − I‖ and on the last row.
    """
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{what} must be a finite 4×4 transform, got shape {T.shape}")
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > tol
        or np.linalg.det(R) < 0
        or np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > tol
    ):
        raise ValueError(
            f"{what} is not a rigid transform (its rotation is not orthonormal with "
            "det +1, or its last row is not [0, 0, 0, 1])"
        )
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4): ``inverse(T_a_b) == T_b_a``."""
    R = T[:3, :3]
    return transform(R.T, -R.T @ T[:3, 3])


def exp_coefficients(theta2: float) -> tuple[float, float, float]:
    """Coefficients of Rodrigues' formula and of its left Jacobian for θ² = |ω|².

    ``exp([ω]×) = I + a[ω]× + b[ω]×²`` and ``V = I + b[ω]× + c[ω]×²`` with a = sin θ/θ,
    b = (1 − cos θ)/θ², c = (θ − sin θ)/θ³; Taylor series below θ = 1e-2, where the closed
    forms lose digits to cancellation.

    Returns:
        ``(a, b, c)``.
    """
    if theta2 < _SERIES:
        t4 = theta2 * theta2
        return (
            1.0 - theta2 / 6.0 + t4 / 120.0,
            0.5 - theta2 / 24.0 + t4 / 720.0,
            1.0 / 6.0 - theta2 / 120.0 + t4 / 5040.0,
        )
    theta = math.sqrt(theta2)
    s = math.sin(theta)
    return s / theta, (1.0 - math.cos(theta)) / theta2, (theta - s) / (theta2 * theta)


def _rodrigues(wx: float, wy: float, wz: float, a: float, b: float) -> list[list[float]]:
    """I + a[ω]× + b[ω]×² as nested lists ([ω]×² = ωωᵀ − θ² I)."""
    th2 = wx * wx + wy * wy + wz * wz
    return [
        [1.0 + b * (wx * wx - th2), b * wx * wy - a * wz, b * wx * wz + a * wy],
        [b * wx * wy + a * wz, 1.0 + b * (wy * wy - th2), b * wy * wz - a * wx],
        [b * wx * wz - a * wy, b * wy * wz + a * wx, 1.0 + b * (wz * wz - th2)],
    ]


def so3_exp(theta_u: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector θu (Rodrigues).

    Args:
        theta_u: (3,) rotation vector [rad].

    Returns:
        (3, 3) rotation matrix.
    """
    wx, wy, wz = np.asarray(theta_u, dtype=float).tolist()  # Python floats, no generator
    a, b, _ = exp_coefficients(wx * wx + wy * wy + wz * wz)
    return np.array(_rodrigues(wx, wy, wz, a, b))


def _shepperd(R: np.ndarray) -> np.ndarray:
    """Unnormalised quaternions (n, 4) wxyz of rotations (n, 3, 3) by Shepperd's method.

    Branch by branch on the largest of (trace, R00, R11, R22): no cancellation in any branch.
    """
    r00, r01, r02 = R[:, 0, 0], R[:, 0, 1], R[:, 0, 2]
    r10, r11, r12 = R[:, 1, 0], R[:, 1, 1], R[:, 1, 2]
    r20, r21, r22 = R[:, 2, 0], R[:, 2, 1], R[:, 2, 2]
    tr = r00 + r11 + r22
    k = np.argmax(np.stack([tr, r00, r11, r22], axis=1), axis=1)
    q = np.empty((len(R), 4))
    for case, m in enumerate(k[None, :] == np.arange(4)[:, None]):
        if not m.any():
            continue
        a00, a01, a02, a10, a11 = r00[m], r01[m], r02[m], r10[m], r11[m]
        a12, a20, a21, a22 = r12[m], r20[m], r21[m], r22[m]
        if case == 0:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack([0.25 * s, (a21 - a12) / s, (a02 - a20) / s, (a10 - a01) / s], 1)
        elif case == 1:
            s = 2.0 * np.sqrt(1.0 + a00 - a11 - a22)
            q[m] = np.stack([(a21 - a12) / s, 0.25 * s, (a01 + a10) / s, (a02 + a20) / s], 1)
        elif case == 2:
            s = 2.0 * np.sqrt(1.0 - a00 + a11 - a22)
            q[m] = np.stack([(a02 - a20) / s, (a01 + a10) / s, 0.25 * s, (a12 + a21) / s], 1)
        else:
            s = 2.0 * np.sqrt(1.0 - a00 - a11 + a22)
            q[m] = np.stack([(a10 - a01) / s, (a02 + a20) / s, (a12 + a21) / s, 0.25 * s], 1)
    return q


def _quat_of_one(R: np.ndarray) -> np.ndarray:
    """One rotation's :func:`quat_wxyz_from_matrix`: _shepperd's operations, on floats."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    tr = r00 + r11 + r22
    case = (tr, r00, r11, r22).index(max(tr, r00, r11, r22))  # as np.argmax: the first maximum
    if case == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif case == 1:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif case == 2:
        s = 2.0 * math.sqrt(1.0 - r00 + r11 - r22)
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 - r00 - r11 + r22)
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    w, x, y, z = q
    f = (-1.0 if w < 0.0 else 1.0) / math.sqrt(w * w + x * x + y * y + z * z)
    return np.array([w * f, x * f, y * f, z * f])


def quat_wxyz_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (w ≥ 0) of rotation matrices, by Shepperd's method.

    Args:
        R: (..., 3, 3) rotation matrices (one, or any stack).

    Returns:
        (..., 4) ``quat_wxyz``.
    """
    R = np.asarray(R, dtype=float)
    if R.shape == (3, 3):
        return _quat_of_one(R)
    q = _shepperd(R.reshape(-1, 3, 3))
    w, x, y, z = q.T
    n = np.sqrt(w * w + x * x + y * y + z * z)
    q = q * (np.where(w < 0.0, -1.0, 1.0) / n)[:, None]
    return q.reshape(*R.shape[:-2], 4)


def quat_xyzw_from_matrix(R: np.ndarray) -> np.ndarray:
    """As :func:`quat_wxyz_from_matrix`, scalar last (scipy's and Rerun's order). (..., 4)."""
    return quat_wxyz_from_matrix(R)[..., [1, 2, 3, 0]]


def matrix_from_quat_wxyz(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices of quaternions; they need not be normalised.

    Args:
        quat_wxyz: (..., 4) quaternions, scalar first. Each must be non-zero and finite.

    Returns:
        (..., 3, 3) rotation matrices.
    """
    q = np.asarray(quat_wxyz, dtype=float)
    if q.shape == (4,):  # one quaternion: the same arithmetic on Python floats, 8× faster
        # (np.linalg.norm's own arithmetic for a vector: the square root of its dot product)
        n = math.sqrt(q.dot(q))
        if not (math.isfinite(n) and n >= 1e-12):
            raise ValueError(f"quaternion {q} is zero or not finite; pass a non-zero finite wxyz")
        w, x, y, z = (q / n).tolist()
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)) or np.any(n < 1e-12):
        raise ValueError(f"quaternion {q} is zero or not finite; pass a non-zero finite wxyz")
    w, x, y, z = np.moveaxis(q / n, -1, 0)
    R = np.stack(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    return np.moveaxis(R, (0, 1), (-2, -1))


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector θu of a rotation matrix, θ ∈ [0, π].

    Robust at θ → 0 and θ → π (computed through the quaternion).

    Args:
        R: (3, 3) rotation matrix.

    Returns:
        (3,) rotation vector [rad].
    """
    q = quat_wxyz_from_matrix(R)
    v = q[1:]
    s = np.linalg.norm(v)
    if s < _SMALL:
        return 2.0 * v / q[0]  # first order: θu ≈ 2 v
    theta = 2.0 * np.arctan2(s, q[0])
    return theta * v / s


def se3_exp(twist: np.ndarray) -> np.ndarray:
    """Exponential map of a twist ``[v, ω]`` (the motion of eq. 9 over unit time).

    Args:
        twist: (6,) ``[v, ω]`` [m, rad] (already multiplied by the time interval).

    Returns:
        (4, 4) rigid transform.
    """
    vx, vy, vz, wx, wy, wz = np.asarray(twist, dtype=float).tolist()
    a, b, c = exp_coefficients(wx * wx + wy * wy + wz * wz)
    R = _rodrigues(wx, wy, wz, a, b)
    V = _rodrigues(wx, wy, wz, b, c)
    t = [V[i][0] * vx + V[i][1] * vy + V[i][2] * vz for i in range(3)]
    return np.array([[*R[0], t[0]], [*R[1], t[1]], [*R[2], t[2]], [0.0, 0.0, 0.0, 1.0]])


def se3_log(T: np.ndarray) -> np.ndarray:
    """Logarithm of a rigid transform, inverse of :func:`se3_exp` (θ < π).

    Args:
        T: (4, 4) rigid transform.

    Returns:
        (6,) twist ``[v, ω]``.
    """
    w = so3_log(T[:3, :3])
    theta2 = float(w @ w)
    K = skew(w)
    if theta2 < _SERIES:
        d = 1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    else:
        theta = np.sqrt(theta2)
        d = (1.0 - theta * np.sin(theta) / (2.0 * (1.0 - np.cos(theta)))) / theta2
    V_inv = np.eye(3) - 0.5 * K + d * (K @ K)
    return np.concatenate([V_inv @ T[:3, 3], w])


def adjoint(T_a_b: np.ndarray) -> np.ndarray:
    """Adjoint of ``T_a_b`` for ``[v, ω]`` twists (eq. 4): maps a twist in F_b to F_a.

    Args:
        T_a_b: (4, 4) rigid transform.

    Returns:
        (6, 6) ``[[R, [t]× R], [0, R]]``.
    """
    R, t = T_a_b[:3, :3], T_a_b[:3, 3]
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[:3, 3:] = skew(t) @ R
    Ad[3:, 3:] = R
    return Ad


def matrix_from_euler_xyz(angles: np.ndarray) -> np.ndarray:
    """R = Rx(a)·Ry(b)·Rz(c) (intrinsic XYZ, scipy ``"XYZ"``) for angles in rad. Returns (3, 3)."""
    a, b, c = angles
    return rot_x(a) @ rot_y(b) @ rot_z(c)


def euler_xyz_from_matrix(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`matrix_from_euler_xyz`; b ∈ [−π/2, π/2]. Returns (3,) rad."""
    b = np.arcsin(np.clip(R[0, 2], -1.0, 1.0))
    if abs(R[0, 2]) < 1.0 - 1e-12:
        a = np.arctan2(-R[1, 2], R[2, 2])
        c = np.arctan2(-R[0, 1], R[0, 0])
    else:  # gimbal lock: only a ± c is defined; put it all in a
        a = np.arctan2(R[2, 1], R[1, 1])
        c = 0.0
    return np.array([a, b, c])


def pose_from_vector(pose: npt.ArrayLike) -> np.ndarray:
    """Transform from a file pose ``[x, y, z, rx, ry, rz]`` (m, degrees, intrinsic XYZ).

    Args:
        pose: (6,) pose as written in scenario files and the paper (a list or an array).

    Returns:
        (4, 4) transform, e.g. ``T_base_platform``.
    """
    p = np.asarray(pose, dtype=float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ValueError(f"pose {p!r} must be 6 finite numbers [x, y, z (m), rx, ry, rz (deg)]")
    return transform(matrix_from_euler_xyz(np.deg2rad(p[3:])), p[:3])


def vector_from_pose(T: np.ndarray) -> np.ndarray:
    """File pose ``[x, y, z, rx, ry, rz]`` (m, degrees) of a transform (4, 4). Returns (6,)."""
    return np.concatenate([T[:3, 3], np.rad2deg(euler_xyz_from_matrix(T[:3, :3]))])


def pose_distance(T_a: np.ndarray, T_b: np.ndarray) -> tuple:
    """Translational [m] and rotational [rad] distance between poses (paper Fig. 5b).

    The rotational distance is the angle θ of the axis-angle form of ``R_aᵀ R_b``, from
    atan2(sin θ, cos θ): accurate at every angle, unlike arccos near 0 and arcsin near π.

    Args:
        T_a: (..., 4, 4) poses.
        T_b: (..., 4, 4) poses (broadcast against ``T_a``).

    Returns:
        ``(translation, rotation)``: floats for single poses, else (...,) arrays.
    """
    T_a, T_b = np.asarray(T_a, dtype=float), np.asarray(T_b, dtype=float)
    d = T_a[..., :3, 3] - T_b[..., :3, 3]
    R = np.swapaxes(T_a[..., :3, :3], -1, -2) @ T_b[..., :3, :3]
    sin2 = np.sqrt(
        (R[..., 2, 1] - R[..., 1, 2]) ** 2
        + (R[..., 0, 2] - R[..., 2, 0]) ** 2
        + (R[..., 1, 0] - R[..., 0, 1]) ** 2
    )
    cos2 = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0
    trans, rot = np.sqrt(np.sum(d * d, axis=-1)), np.arctan2(sin2, cos2)
    if trans.ndim == 0:
        return float(trans), float(rot)
    return trans, rot


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> dict:
    """JSON-ready distance between two poses (metres and degrees)."""
    dt, dr = pose_distance(T_a, T_b)
    return {"translation_m": dt, "rotation_deg": float(np.degrees(dr))}


def covariance_ellipsoids(P: np.ndarray, sigmas: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Half-axes [m] and orientations (quaternions x, y, z, w) of (n, 3, 3) covariances.

    The ``sigmas``-σ ellipsoid of each covariance: half-axes (n, 3), quaternions (n, 4).
    """
    values, vectors = np.linalg.eigh(np.nan_to_num(P))
    vectors[np.linalg.det(vectors) < 0, :, 2] *= -1.0  # right-handed axes
    half = sigmas * np.sqrt(np.maximum(values, 0.0))
    return half, quat_xyzw_from_matrix(vectors)
