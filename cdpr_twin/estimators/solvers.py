"""The least-squares solvers of the model-based estimators (Algorithm 1), numpy and scipy.

Two backends solve the same square system lengths(T) = targets and agree to round-off:

- ``"scipy"`` — the paper's formulation: ``scipy.optimize.least_squares`` over
  [x, y, z, q1, q2, q3, q4] (q scalar first) with the six residuals and the unit-quaternion
  equation f7 = |q|² − 1.
- ``"fast"`` (default) — Newton on SE(3): T ← T·exp(δ) with A δ = −r, A the analytic
  platform-frame Jacobian of the six lengths (eq. 6, or its pulley form), step halving when the
  residual does not decrease.

:func:`gauss_newton` is the weighted, over-determined form (any number of cables ≥ 6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.linalg.lapack import dgesv
from scipy.optimize import least_squares

from cdpr_twin.math.kinematics import lengths_and_jacobian
from cdpr_twin.math.se3 import (
    exp_coefficients,
    matrix_from_quat_wxyz,
    quat_wxyz_from_matrix,
    transform,
)

Backend = Literal["fast", "scipy"]
N_USED = 6


Pose = tuple[float, ...]
"""A pose as 12 floats: R row-major (9), then t (3)."""


@dataclass(frozen=True, eq=False)
class PoseSolution:
    """A platform pose solved from six cable lengths.

    Attributes:
        T: (4, 4) the pose.
        residual: the largest |lengths(T) − targets| [m].
        iterations: Newton steps taken (SciPy: residual evaluations).
    """

    T: np.ndarray
    residual: float
    iterations: int


@dataclass(frozen=True, eq=False)
class WeightedSolution:
    """A platform pose fitted by weighted least squares to any number (≥ 6) of cable lengths.

    Attributes:
        T: (4, 4) the pose.
        residuals: (k,) lengths(T) − targets [m].
        iterations: Gauss-Newton steps taken (SciPy: residual evaluations).
        converged: whether the solver met its own stopping test.
    """

    T: np.ndarray
    residuals: np.ndarray
    iterations: int
    converged: bool

    @property
    def largest_residual(self) -> float:
        """Max |residuals| [m]."""
        return float(np.max(np.abs(self.residuals)))


_POSE_IDX = (0, 1, 2, 4, 5, 6, 8, 9, 10, 3, 7, 11)  # from the first 3 rows of T, row-major


def _kernel(
    cables: list[tuple[float, ...]], pulley: bool, pose: Pose
) -> tuple[list[float], list[list[float]]]:
    """Lengths and platform-frame Jacobian rows of a few cables, in scalar arithmetic.

    The same equations as :func:`cdpr_twin.math.kinematics.lengths_and_jacobian` (eq. 6-7, 15-24),
    written with ``math`` on floats: for six cables this is several times faster than numpy on
    (6, 3) arrays, whose per-call overhead dominates at that size.

    Args:
        cables: per cable ``(ax, ay, az, bx, by, bz, r)``: exit point in F_b, anchor point in
            F_p, sheave radius [m].
        pulley: pulley lengths (eq. 15-24) or straight ones (eq. 7).
        pose: platform pose as 12 floats (:data:`Pose`).

    Returns:
        ``(lengths, rows)``: lengths [m] and the Jacobian rows ``[u_p, b_p × u_p]``.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = pose
    lengths: list[float] = []
    rows: list[list[float]] = []
    sqrt, atan2, asin = math.sqrt, math.atan2, math.asin
    for ax, ay, az, px, py, pz, r in cables:
        bx = r00 * px + r01 * py + r02 * pz + t0
        by = r10 * px + r11 * py + r12 * pz + t1
        bz = r20 * px + r21 * py + r22 * pz + t2
        lx, ly, lz = bx - ax, by - ay, bz - az
        if pulley:
            h = sqrt(lx * lx + ly * ly)
            cx, cy = lx / h, ly / h  # x_i (eq. 20-22)
            mx, my, mz = lx - r * cx, ly - r * cy, lz  # m_i = b_i - n_i (eq. 21, 23)
            mn = sqrt(mx * mx + my * my + mz * mz)
            free = sqrt(mn * mn - r * r)  # eq. 24
            length = free + r * (math.pi - atan2(free, r) - asin(-mz / mn))  # eq. 15-19
            eh, ez = (mx * cx + my * cy) / mn, mz / mn
            cp, sp = r / mn, free / mn
            ch, cz = r * (cp * eh + sp * ez), r * (cp * ez - sp * eh)  # tangent point - n_i
            ux, uy, uz = (mx - ch * cx) / free, (my - ch * cy) / free, (mz - cz) / free
        else:
            length = sqrt(lx * lx + ly * ly + lz * lz)
            ux, uy, uz = lx / length, ly / length, lz / length
        vx = r00 * ux + r10 * uy + r20 * uz  # u_p = Rᵀ u
        vy = r01 * ux + r11 * uy + r21 * uz
        vz = r02 * ux + r12 * uy + r22 * uz
        lengths.append(length)
        rows.append([vx, vy, vz, py * vz - pz * vy, pz * vx - px * vz, px * vy - py * vx])
    return lengths, rows


def exp_terms(
    vx: float,
    vy: float,
    vz: float,
    wx: float,
    wy: float,
    wz: float,
    th2: float,
    a: float,
    b: float,
    c: float,
) -> tuple[float, ...]:
    """exp(d) of a twist d = [v, ω] as 12 floats: its rotation row-major (9), then V·v (3).

    dR = I + a[ω]× + b[ω]×², V = I + b[ω]× + c[ω]×², with [ω]×² = ωωᵀ − θ² I and (a, b, c) the
    coefficients of :func:`cdpr_twin.math.se3.exp_coefficients` for θ² = ``th2``. Plain float
    arithmetic: :mod:`cdpr_twin.estimators.newton` compiles this same function.
    """
    xx, yy, zz, xy, xz, yz = wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz
    d00, d11, d22 = 1.0 + b * (xx - th2), 1.0 + b * (yy - th2), 1.0 + b * (zz - th2)
    d01, d10 = b * xy - a * wz, b * xy + a * wz
    d02, d20 = b * xz + a * wy, b * xz - a * wy
    d12, d21 = b * yz - a * wx, b * yz + a * wx
    px = (1.0 + c * (xx - th2)) * vx + (c * xy - b * wz) * vy + (c * xz + b * wy) * vz
    py = (c * xy + b * wz) * vx + (1.0 + c * (yy - th2)) * vy + (c * yz - b * wx) * vz
    pz = (c * xz - b * wy) * vx + (c * yz + b * wx) * vy + (1.0 + c * (zz - th2)) * vz
    return d00, d01, d02, d10, d11, d12, d20, d21, d22, px, py, pz


def _compose_exp(pose: Pose, d: list[float]) -> Pose:
    """``pose · exp(d)`` for a twist d = [v, ω] in the platform frame, in scalar arithmetic.

    The same map as :func:`cdpr_twin.math.se3.se3_exp` (Rodrigues and its left Jacobian).
    """
    vx, vy, vz, wx, wy, wz = d
    th2 = wx * wx + wy * wy + wz * wz
    terms = exp_terms(vx, vy, vz, wx, wy, wz, th2, *exp_coefficients(th2))
    d00, d01, d02, d10, d11, d12, d20, d21, d22, px, py, pz = terms
    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = pose
    return (
        r00 * d00 + r01 * d10 + r02 * d20,
        r00 * d01 + r01 * d11 + r02 * d21,
        r00 * d02 + r01 * d12 + r02 * d22,
        r10 * d00 + r11 * d10 + r12 * d20,
        r10 * d01 + r11 * d11 + r12 * d21,
        r10 * d02 + r11 * d12 + r12 * d22,
        r20 * d00 + r21 * d10 + r22 * d20,
        r20 * d01 + r21 * d11 + r22 * d21,
        r20 * d02 + r21 * d12 + r22 * d22,
        t0 + r00 * px + r01 * py + r02 * pz,
        t1 + r10 * px + r11 * py + r12 * pz,
        t2 + r20 * px + r21 * py + r22 * pz,
    )


def _cable_tuples(
    a_base: np.ndarray, b_platform: np.ndarray, pulley_radius: np.ndarray | None
) -> list[tuple[float, ...]]:
    radii = np.zeros(len(a_base)) if pulley_radius is None else pulley_radius
    return [tuple(v) for v in np.column_stack([a_base, b_platform, radii]).tolist()]


def solve_fast(
    a_base: np.ndarray,
    b_platform: np.ndarray,
    pulley_radius: np.ndarray | None,
    targets: np.ndarray,
    T0: np.ndarray,
    max_iterations: int = 30,
    tol: float = 1e-12,
) -> PoseSolution:
    """Newton solve of lengths(T) = targets on SE(3) from T0.

    Args:
        a_base: (6, 3) exit points of the cables used [m].
        b_platform: (6, 3) their anchor points [m].
        pulley_radius: (6,) their sheave radii [m], or ``None`` for straight cables.
        targets: (6,) measured (possibly stretch-corrected) lengths [m].
        T0: (4, 4) initial guess.
        max_iterations: iteration cap.
        tol: stop when every residual is below this [m].

    Returns:
        The pose, its largest length residual and the steps taken.
    """
    return _newton(
        _cable_tuples(a_base, b_platform, pulley_radius),
        pulley_radius is not None,
        np.asarray(targets, dtype=float),
        T0,
        max_iterations,
        tol,
    )


def _newton(
    cables: list[tuple[float, ...]],
    pulley: bool,
    goal: np.ndarray,
    T0: np.ndarray,
    max_iterations: int = 30,
    tol: float = 1e-12,
) -> PoseSolution:
    pose = _pose(T0)
    target = goal.tolist() if isinstance(goal, np.ndarray) else goal
    lengths, rows = _kernel(cables, pulley, pose)
    r = [x - y for x, y in zip(lengths, target, strict=True)]
    cost = sum(x * x for x in r)
    it = 0
    while it < max_iterations and max(map(abs, r)) > tol:
        it += 1
        A = np.array(rows)
        neg_r = np.array([-x for x in r])
        _, _, x, info = dgesv(A, neg_r)  # LAPACK directly: np.linalg.solve costs 5× more here
        if info != 0:  # singular pose: take the least-squares step
            x = np.linalg.lstsq(A, neg_r, rcond=None)[0]
        delta = x.tolist()
        if not math.isfinite(sum(x * x for x in delta)):  # e.g. an infinite target: stop
            break
        step = 1.0
        for _ in range(30):  # step halving keeps the cost decreasing far from the root
            pose_new = _compose_exp(pose, [step * x for x in delta])
            lengths_new, rows_new = _kernel(cables, pulley, pose_new)
            r_new = [x - y for x, y in zip(lengths_new, target, strict=True)]
            cost_new = sum(x * x for x in r_new)
            if cost_new <= cost:
                break
            step *= 0.5
        else:
            break
        pose, rows, r, cost = pose_new, rows_new, r_new, cost_new
    return PoseSolution(_matrix(pose), max(map(abs, r)), it)


def _pose(T: np.ndarray) -> Pose:
    """The 12 floats of a (4, 4) pose (:data:`Pose`)."""
    v = T[:3].ravel().tolist()
    return tuple(v[i] for i in _POSE_IDX)


def _matrix(p: Pose) -> np.ndarray:
    """The (4, 4) pose of 12 floats (:data:`Pose`)."""
    return np.array(
        [
            [p[0], p[1], p[2], p[9]],
            [p[3], p[4], p[5], p[10]],
            [p[6], p[7], p[8], p[11]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


@np.errstate(over="ignore", invalid="ignore")  # huge targets: an infinite cost, not a warning
def gauss_newton(
    cables: list[tuple[float, ...]],
    pulley: bool,
    goal: np.ndarray,
    weights: np.ndarray,
    T0: np.ndarray,
    max_iterations: int = 30,
    tol: float = 1e-11,
) -> WeightedSolution:
    """Weighted least squares min Σ w_i (l_i(T) − goal_i)² on SE(3), from T0.

    Gauss-Newton steps T ← T·exp(δ), (AᵀWA) δ = −AᵀW r, halved while the cost grows.

    Args:
        cables: k ≥ 6 cables as :func:`_kernel` takes them.
        pulley: pulley lengths (eq. 15-24) or straight ones.
        goal: (k,) measured (possibly stretch-corrected) lengths [m].
        weights: (k,) weights 1/σ_i² [1/m²].
        T0: (4, 4) initial guess.
        max_iterations: iteration cap.
        tol: converged when the step's largest component is below this [m, rad].

    Returns:
        The pose, its (k,) residuals lengths(T) − goal [m], the steps taken and whether the
        last step fell below ``tol``.
    """
    pose = _pose(T0)
    sw = np.sqrt(np.asarray(weights, dtype=float))
    goal = np.asarray(goal, dtype=float)
    lengths, rows = _kernel(cables, pulley, pose)
    r = np.asarray(lengths) - goal
    cost = float(np.sum((sw * r) ** 2))
    if not math.isfinite(cost):  # e.g. an infinite target or weight: no step, not converged
        return WeightedSolution(_matrix(pose), r, 0, False)
    for it in range(1, max_iterations + 1):
        x = np.linalg.lstsq(np.asarray(rows) * sw[:, None], -sw * r, rcond=None)[0]
        if not math.isfinite(x @ x):  # huge targets with small weights: a finite cost, no step
            return WeightedSolution(_matrix(pose), r, it, False)
        if np.max(np.abs(x)) < tol:
            return WeightedSolution(_matrix(pose), r, it, True)
        step = 1.0
        for _ in range(30):
            pose_new = _compose_exp(pose, (step * x).tolist())
            lengths_new, rows_new = _kernel(cables, pulley, pose_new)
            r_new = np.asarray(lengths_new) - goal
            cost_new = float(np.sum((sw * r_new) ** 2))
            if cost_new <= cost:
                break
            step *= 0.5
        else:  # no decrease along the step: at the minimum to round-off
            return WeightedSolution(_matrix(pose), r, it, bool(step * np.max(np.abs(x)) < tol))
        pose, rows, r, cost = pose_new, rows_new, r_new, cost_new
    return WeightedSolution(_matrix(pose), r, max_iterations, False)


def solve_scipy(
    a_base: np.ndarray,
    b_platform: np.ndarray,
    pulley_radius: np.ndarray | None,
    targets: np.ndarray,
    T0: np.ndarray,
    x0: np.ndarray | None = None,
) -> PoseSolution:
    """The paper's Algorithm 1 with ``scipy.optimize.least_squares`` (7 unknowns, 7 equations).

    Arguments and return value as :func:`solve_fast`; ``x0`` optionally gives the initial
    unknowns [x, y, z, q1, q2, q3, q4] (q scalar first, any sign or norm) instead of ``T0``.
    """

    def residuals(x: np.ndarray) -> np.ndarray:
        q = x[3:]
        T = transform(matrix_from_quat_wxyz(q), x[:3])
        lengths, _ = lengths_and_jacobian(a_base, b_platform, pulley_radius, T)
        return np.append(lengths - targets, q @ q - 1.0)  # f1…f6, f7

    if x0 is None:
        x0 = np.concatenate([T0[:3, 3], quat_wxyz_from_matrix(T0[:3, :3])])
    sol = least_squares(residuals, x0, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    T = transform(matrix_from_quat_wxyz(sol.x[3:]), sol.x[:3])
    return PoseSolution(T, float(np.max(np.abs(sol.fun[:N_USED]))), int(sol.nfev))
