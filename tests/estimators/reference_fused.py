"""NumPy references of the fused filter's compiled arithmetic, for the tests only.

The filter runs the Numba versions (:mod:`cdpr_twin.estimators.fused_core`,
:mod:`cdpr_twin.estimators.compiled_kernels`); these are the same equations written plainly, one
formula a line, so that ``test_fused_core.py`` and ``test_fused.py`` can hold the compiled ones
to them. The models they follow are described in :mod:`cdpr_twin.estimators.fused_models`.
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.estimators import fused_models as fm
from cdpr_twin.math.se3 import adjoint, inverse, se3_exp, se3_log


def tag_covariance(
    T_cam_tag: np.ndarray, tag_size: float, focal_px: float, pixel_std: float
) -> np.ndarray:
    """Covariance of the detection noise n (tag frame, [v, ω]) from the corners' pixel noise.

    R = σ² (JᵀJ)⁻¹ with J the (8, 6) Jacobian of the four corners' pixel coordinates with
    respect to n: it grows with the tag's distance (roughly as its square for depth).

    Args:
        T_cam_tag: (4, 4) detected tag pose in the camera frame.
        tag_size: edge of the tag's black square [m].
        focal_px: focal length [px] (square pixels).
        pixel_std: std of a corner's pixel coordinates [px].

    Returns:
        (6, 6) covariance [m², m·rad, rad²].
    """
    J = fm._corner_jacobian(T_cam_tag, tag_size, focal_px)[0]  # pinhole: the lens changes this
    return pixel_std**2 * np.linalg.inv(J.T @ J)  # by ~k1·r² (≲ 1 %), within pixel_std's doubt


def tag_residual(
    T_base_platform: np.ndarray,
    T_base_tag: np.ndarray,
    T_platform_cam: np.ndarray,
    T_cam_tag: np.ndarray,
    lag_twist: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Innovation of a tag detection and its Jacobian with respect to δ (the tag's is I).

    Args:
        T_base_platform: (4, 4) current pose estimate.
        T_base_tag: (4, 4) the tag's estimated pose in F_b.
        T_platform_cam: (4, 4) the camera mounting.
        T_cam_tag: (4, 4) the detection.
        lag_twist: (6,) ξ·d, the platform motion over the frame's latency (F_p) [m, rad].

    Returns:
        ``(r, H_pose, z_hat)``: (6,) log(ẑ⁻¹ z) in the tag frame, (6, 6) ∂r/∂δ and the
        (4, 4) predicted detection ẑ.
    """
    T_lag = T_base_platform @ se3_exp(-lag_twist)
    M = inverse(T_lag) @ T_base_tag  # ᵖT_o at the frame's time
    z_hat = inverse(T_platform_cam) @ M
    r = se3_log(inverse(z_hat) @ T_cam_tag)
    return r, -adjoint(inverse(M)) @ adjoint(se3_exp(lag_twist)), z_hat


def joseph_update(
    P: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    innovation: np.ndarray,
    corrected: int | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """One Kalman update in Joseph form, optionally with "consider" states (Schmidt).

    The Joseph form P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ is the covariance of the update for any
    gain K, so zeroing the gain of some states keeps P exact: those states are *considered*
    (their uncertainty and correlations shape every update) but never corrected, and what the
    data seem to say about them is not believed. It is evaluated as
    P⁺ = P − K(HP) − (HP)ᵀKᵀ + K S Kᵀ (S = HPHᵀ + R), the same matrix in O(n²k) rather than
    O(n³) (algebraically equal; the product form's built-in symmetry and positive
    semi-definiteness are restored by symmetrising, and a test holds it to the product form):
    with the considered states last, only the leading rows and columns change.

    Args:
        P: (n, n) prior covariance.
        H: (k, n) measurement Jacobian.
        R: (k, k) measurement noise covariance.
        innovation: (k,) measured − predicted.
        corrected: the number c of leading states corrected; the others are considered
            (``None``: all corrected).

    Returns:
        ``(dx, P_post, nis)``: (n,) correction, (n, n) posterior covariance and the
        normalised innovation squared.
    """
    c = len(P) if corrected is None else corrected
    PHt = P @ H.T
    S = H @ PHt + R
    S_inv = np.linalg.inv(S)
    K = PHt[:c] @ S_inv  # (c, k): the considered states' gain is zero
    KHP = K @ PHt.T  # (c, n)
    P_post = P.copy()
    P_post[:c] -= KHP
    P_post[:, :c] -= KHP.T
    P_post[:c, :c] += K @ S @ K.T
    dx = np.zeros(len(P))
    dx[:c] = K @ innovation
    return dx, 0.5 * (P_post + P_post.T), float(innovation @ S_inv @ innovation)


def geometry_rows(layout: fm.Layout, rows: np.ndarray, R: np.ndarray) -> np.ndarray:
    """∂L/∂(exit points, anchor points) of every cable at one pose, as (m, n) state columns.

    ∂L_i/∂a_i = −u_i (F_b) and ∂L_i/∂b_i = Rᵀu_i (F_p), u_i the free segment's direction (the
    pulley's small change of wrap is left out).

    Args:
        layout: the state layout (zero columns when the geometry is not modelled).
        rows: (m, 6) platform-frame Jacobian rows [u_p, b × u_p] at the pose.
        R: (3, 3) the pose's rotation.
    """
    m = len(rows)
    G = np.zeros((m, layout.n))
    if layout.exit.stop == layout.exit.start:
        return G
    u_p = rows[:, :3]
    idx = np.arange(m)
    cols = 3 * idx[:, None] + np.arange(3)  # (m, 3): cable i's three columns
    G[idx[:, None], layout.exit.start + cols] = -(u_p @ R.T)
    G[idx[:, None], layout.anchor.start + cols] = u_p
    return G
