"""A calibration's tag view residuals; their derivatives over camera, tag and intrinsics.

The prediction of a view is ᵖT_c⁻¹ · ᵇT_p,k⁻¹ · ᵇT_o · exp(G_k δk)
(:class:`~cdpr_twin.calibrate.problem.Problem` states the model). The twenty shared parameters
it depends on are differentiated together (:func:`view_jacobian`): every perturbed prediction
in one vectorised evaluation, where central differences column by column would evaluate every
view 40 times.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cdpr_twin.calibrate.parameter_layout import Layout

SHARED = (("camera", 0), ("tag", 6), ("intrinsics", 12))
"""The shared blocks a view depends on, and where each sits in :func:`view_jacobian`'s stack."""


def exp_stack(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of a stack of twists ``[v, ω]`` (K, 6). Returns (K, 4, 4)."""
    v, w = xi[:, :3], xi[:, 3:]
    th2 = np.einsum("ij,ij->i", w, w)
    small = th2 < 1e-8
    th = np.sqrt(np.where(small, 1.0, th2))
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / np.where(small, 1.0, th2))
    c = np.where(small, 1.0 / 6.0 - th2 / 120.0, (th - np.sin(th)) / (th * th * th))
    K = np.zeros((len(xi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K = K - K.transpose(0, 2, 1)
    V = np.eye(3) + b[:, None, None] * K + c[:, None, None] * (K @ K)
    T = np.zeros((len(xi), 4, 4))
    T[:, :3, :3] = Rotation.from_rotvec(w).as_matrix()
    T[:, :3, 3] = np.einsum("nij,nj->ni", V, v)
    T[:, 3, 3] = 1.0
    return T


def inverse_stack(T: np.ndarray) -> np.ndarray:
    """Inverse of a stack of rigid transforms (..., 4, 4)."""
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def predicted_tags(problem, T_cam_platform, T_base_tag, intrinsics, poses) -> np.ndarray:
    """The views a stack of q models predicts where the tag was seen.

    Args:
        problem: the :class:`~cdpr_twin.calibrate.problem.Problem` (which poses saw the tag,
            each view's intrinsics Jacobian G).
        T_cam_platform: (q, 4, 4) the camera mounts, inverted.
        T_base_tag: (q, 4, 4) the tag poses.
        intrinsics: (q, 8) the detector's intrinsics errors.
        poses: (K, 4, 4) the platform poses (the same for the q models).

    Returns:
        (q, n_seen, 4, 4) ᶜT_o.
    """
    pred = T_cam_platform[:, None] @ inverse_stack(poses[problem.seen])[None]
    pred = pred @ T_base_tag[:, None]
    G = problem.intrinsics_jacobian
    if G is not None:  # what the detector's intrinsics error does to each view
        E = exp_stack(np.einsum("sij,qj->qsi", G, intrinsics).reshape(-1, 6))
        pred = pred @ E.reshape(pred.shape)
    return pred


def tag_residuals(problem, pred: np.ndarray) -> np.ndarray:
    """Measured against predicted views, over their noise: (q, n_seen, 4, 4) → (q, 6 n_seen)."""
    n = problem.noise
    meas = problem.obs.T_cam_tag[problem.seen]
    d = np.linalg.norm(meas[:, :3, 3], axis=1)[:, None]
    std = np.array([n.tag_lateral_std, n.tag_lateral_std, n.tag_depth_std])
    per_m = np.array([n.tag_std_per_m, n.tag_std_per_m, n.depth_growth])
    dt = (meas[:, :3, 3] - pred[..., :3, 3]) / (std + per_m * d)
    R = np.swapaxes(pred[..., :3, :3], -1, -2) @ meas[:, :3, :3]
    dr = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(dt.shape)
    return np.concatenate([dt, dr / n.tag_rotation_std], axis=-1).reshape(len(pred), -1)


def view_columns(layout: Layout) -> list[int]:
    """The columns :func:`view_jacobian` gives (camera, tag, intrinsics: those estimated)."""
    return [c for name, _ in SHARED for c in layout.columns(name)]


def view_jacobian(problem, x: np.ndarray, h: float) -> np.ndarray:
    """Central differences of the tag residuals over the camera, tag and intrinsics columns.

    Args:
        problem: as :func:`predicted_tags`.
        x: (n,) where to differentiate.
        h: step [m, rad or px].

    Returns:
        (6 n_seen, len(view_columns)), columns as :func:`view_columns` orders them.
    """
    L = problem.layout
    moved = [at + j for name, at in SHARED for j in range(len(L.columns(name)))]
    if not moved or not len(problem.seen):
        return np.zeros((6 * len(problem.seen), len(moved)))
    P = np.tile(np.concatenate([L.get(x, name) for name, _ in SHARED]), (2 * len(moved), 1))
    P[2 * np.arange(len(moved)), moved] += h
    P[2 * np.arange(len(moved)) + 1, moved] -= h
    g = problem.nominal
    C = inverse_stack(g.T_platform_cam @ exp_stack(P[:, :6]))
    T = problem.T_base_tag @ exp_stack(P[:, 6:12])
    poses = problem.model(x).T_base_platform
    r = tag_residuals(problem, predicted_tags(problem, C, T, P[:, 12:], poses))
    return ((r[0::2] - r[1::2]) / (2.0 * h)).T
