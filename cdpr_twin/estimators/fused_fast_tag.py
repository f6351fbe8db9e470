"""Fast paths of the fused filter's tag update, bit-identical to the reference.

The detection's noise and calibration Jacobian (:mod:`cdpr_twin.estimators.fused_models`) and
the residual's SE(3) algebra (:mod:`cdpr_twin.se3`), computed as
:mod:`cdpr_twin.estimators.fused_fast` explains: the same floating-point operations, fewer
NumPy calls. Tests hold each function to its reference bit for bit.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from cdpr_twin.estimators.fused_fast import adjoint
from cdpr_twin.se3 import _SERIES, _SMALL, _quat_of_one, inverse, se3_exp

_NO_LENS = (0.0, 0.0, 0.0, 0.0)


@lru_cache(maxsize=4)
def _tag_corners(tag_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The tag's corners p (4, 3) in its frame [m] and −[p]× (4, 3, 3), read-only.

    Built as ``fused_models._corner_jacobian`` builds them.
    """
    h = 0.5 * tag_size
    p = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    cross = np.zeros((4, 3, 3))  # −[p]×
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = p[:, 2], -p[:, 1], p[:, 0]
    cross[:, 1, 0], cross[:, 2, 0], cross[:, 2, 1] = -p[:, 2], p[:, 1], -p[:, 0]
    p.flags.writeable = cross.flags.writeable = False
    return p, cross


@lru_cache(maxsize=4)
def _pinhole(focal_px: float) -> np.ndarray:
    """``_lens_pixels``'s (4, 2, 2) for the zero lens at finite points: [[f, 0], [0, f]] each.

    With k1 = k2 = p1 = p2 = 0, a = 1 + 0·r² + 0·r²·r² = 1 and every other term is a zero, so
    the diagonal is f·1 = f; the off-diagonal is a sum of signed zeros whose signs (of xy, x
    and y) cannot all be negative: +0 (f > 0).
    """
    out = np.array([[[focal_px, 0.0], [0.0, focal_px]]] * 4)
    out.flags.writeable = False
    return out


def _lens_pixels(
    points: list[tuple[float, float]], coeffs, focal_px: float
) -> tuple[np.ndarray, list[float]]:
    """``fused_models._lens`` on floats, corner by corner, scaled as ``_corner_jacobian`` uses it.

    Args:
        points: 4 undistorted normalised points (x, y).
        coeffs: (k1, k2, p1, p2).
        focal_px: focal length [px].

    Returns:
        (4, 2, 2) ``focal_px · ∂(distorted)/∂(point)`` and the 64 entries (row-major) of Π
        (8, 8), the pixels' Jacobian with respect to (fx, fy, cx, cy, k1, k2, p1, p2).
    """
    k1, k2, p1, p2 = coeffs
    fD: list[float] = []
    Pi: list[float] = []
    for x, y in points:
        r2 = x * x + y * y
        a, da = 1.0 + k1 * r2 + k2 * r2 * r2, 2.0 * k1 + 4.0 * k2 * r2
        xd = x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        d01 = focal_px * (x * y * da + 2 * p1 * x + 2 * p2 * y)
        d00 = focal_px * (a + x * x * da + 2 * p1 * y + 6 * p2 * x)
        fD += (d00, d01, d01, focal_px * (a + y * y * da + 6 * p1 * y + 2 * p2 * x))
        dx = (x * r2, x * r2 * r2, 2 * x * y, r2 + 2 * x * x)
        dy = (y * r2, y * r2 * r2, r2 + 2 * y * y, 2 * x * y)
        Pi += (xd, 0.0, 1.0, 0.0, *(focal_px * v for v in dx))
        Pi += (0.0, yd, 0.0, 1.0, *(focal_px * v for v in dy))
    return np.array(fD).reshape(4, 2, 2), Pi


def tag_noise(
    T_cam_tag: np.ndarray,
    tag_size: float,
    focal_px: float,
    pixel_std: float,
    lens,
    calibration: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """A detection's noise covariance and its calibration Jacobian, sharing their work.

    Bit for bit ``(fused_models.tag_covariance(T_cam_tag, tag_size, focal_px, pixel_std),
    fused_models.tag_calibration_jacobian(T_cam_tag, tag_size, focal_px, lens))``.

    Args:
        T_cam_tag: (4, 4) detected tag pose in the camera frame.
        tag_size: edge of the tag's black square [m].
        focal_px: focal length [px].
        pixel_std: std of a corner's pixel coordinates [px].
        lens: the calibrated (k1, k2, p1, p2).
        calibration: whether to compute the calibration Jacobian (else ``None``).

    Returns:
        (6, 6) covariance [m², m·rad, rad²] and (6, 8) ∂n/∂δk, or ``None``.
    """
    p, cross = _tag_corners(tag_size)
    R, t = T_cam_tag[:3, :3], T_cam_tag[:3, 3]
    norm: list[float] = []
    points = []
    for X, Y, Z in (p @ R.T + t).tolist():  # the corners in the camera frame
        inv_z = 1.0 / Z
        norm += (inv_z, 0.0, -inv_z * X / Z, 0.0, inv_z, -inv_z * Y / Z)
        points.append((X * inv_z, Y * inv_z))
    d_norm = np.array(norm).reshape(4, 2, 3)  # d(x, y)/dX
    d_point = np.zeros((4, 3, 6))  # dX/d[v, ω] = R [I, −[p]×]
    d_point[:, :, :3] = R
    d_point[:, :, 3:] = R @ cross
    if max(abs(v) for xy in points for v in xy) < 1e100:  # the covariance is the pinhole's:
        fD = _pinhole(focal_px)  # what the zero lens gives at any point with a finite r²
    else:
        fD = _lens_pixels(points, _NO_LENS, focal_px)[0]
    J = (fD @ d_norm @ d_point).reshape(8, 6)
    cov = pixel_std**2 * np.linalg.inv(J.T @ J)
    if not calibration:
        return cov, None
    fD, Pi = _lens_pixels(points, lens, focal_px)
    J = (fD @ d_norm @ d_point).reshape(8, 6)
    return cov, -np.linalg.solve(J.T @ J, J.T @ np.array(Pi).reshape(8, 8))


def se3_log(T: np.ndarray) -> np.ndarray:
    """``se3.se3_log`` of one (4, 4) float array, bit for bit: (6,) twist ``[v, ω]``."""
    q = _quat_of_one(T[:3, :3])
    v = q[1:]
    s = np.sqrt(v.dot(v))  # np.linalg.norm(v)
    q0, vx, vy, vz = q.tolist()
    if s < _SMALL:
        w = [2.0 * vx / q0, 2.0 * vy / q0, 2.0 * vz / q0]  # first order: θu ≈ 2 v
    else:
        theta = 2.0 * np.arctan2(s, q[0])
        w = [theta * vx / s, theta * vy / s, theta * vz / s]
    x, y, z = w
    w_arr = np.array(w)
    theta2 = float(w_arr @ w_arr)
    K = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]  # [ω]×
    if theta2 < _SERIES:
        d = 1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    else:
        theta = np.sqrt(theta2)
        d = (1.0 - theta * np.sin(theta) / (2.0 * (1.0 - np.cos(theta)))) / theta2
    K_arr = np.array(K)
    KK = (K_arr @ K_arr).tolist()
    V_inv = [(float(i == j) - 0.5 * K[i][j]) + d * KK[i][j] for i in range(3) for j in range(3)]
    return np.array([*(np.array(V_inv).reshape(3, 3) @ T[:3, 3]).tolist(), *w])


def tag_residual(
    T_base_platform: np.ndarray,
    T_base_tag: np.ndarray,
    T_cam_platform: np.ndarray,
    T_cam_tag: np.ndarray,
    lag_twist: list[float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``fused_models.tag_residual``, bit for bit, given ``T_cam_platform = inverse(T_pc)``.

    Args:
        T_base_platform: (4, 4) current pose estimate.
        T_base_tag: (4, 4) the tag's estimated pose in F_b.
        T_cam_platform: (4, 4) ``se3.inverse`` of the camera mounting.
        T_cam_tag: (4, 4) the detection.
        lag_twist: 6 floats, ξ·d (F_p) [m, rad].

    Returns:
        ``(r, H_pose, z_hat)``: (6,) innovation, (6, 6) ∂r/∂δ, (4, 4) predicted detection.
    """
    T_lag = T_base_platform @ se3_exp([-v for v in lag_twist])
    M = inverse(T_lag) @ T_base_tag  # ᵖT_o at the frame's time
    z_hat = T_cam_platform @ M
    r = se3_log(inverse(z_hat) @ T_cam_tag)
    return r, -adjoint(M, invert=True) @ adjoint(se3_exp(lag_twist)), z_hat
