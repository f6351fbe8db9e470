"""Est. 3-6, model-based: Algorithm 1 on the six most-tensioned cables (paper §III-C).

The measured lengths are the winch encoders' (unstretched) lengths, corrected for stretch
(eq. 13-14, τ(0) = 0) in the ``elastic`` variants; the model lengths are straight A_i-B_i
segments or pulley lengths (eq. 15-24). The pose is the root of the six length residuals near
the last estimate, using the *nominal* geometry, E·S and r_p.

Two backends solve the same square system and agree to round-off:

- ``"scipy"`` — the paper's formulation: ``scipy.optimize.least_squares`` over
  [x, y, z, q1, q2, q3, q4] (q scalar first) with the six residuals and the unit-quaternion
  equation f7 = |q|² − 1.
- ``"fast"`` (default) — Newton on SE(3): T ← T·exp(δ) with A δ = −r, A the analytic
  platform-frame Jacobian of the six lengths (eq. 6, or its pulley form), step halving when the
  residual does not decrease.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from scipy.linalg.lapack import dgesv
from scipy.optimize import least_squares

from cdpr_twin.estimators.base import (
    FEW_TAUT_CABLES,
    NO_INPUTS,
    NON_FINITE_INPUT,
    NOT_CONVERGED,
    Estimator,
)
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.kinematics import elastic_elongation, lengths_and_jacobian
from cdpr_twin.plugins import OptionError, option, register
from cdpr_twin.se3 import exp_coefficients, matrix_from_quat_wxyz, quat_wxyz_from_matrix, transform
from cdpr_twin.types import Measurement, PoseEstimate

Backend = Literal["fast", "scipy"]
N_USED = 6


Pose = tuple[float, ...]
"""A pose as 12 floats: R row-major (9), then t (3)."""
_POSE_IDX = (0, 1, 2, 4, 5, 6, 8, 9, 10, 3, 7, 11)  # from the first 3 rows of T, row-major


def _kernel(
    cables: list[tuple[float, ...]], pulley: bool, pose: Pose
) -> tuple[list[float], list[list[float]]]:
    """Lengths and platform-frame Jacobian rows of a few cables, in scalar arithmetic.

    The same equations as :func:`cdpr_twin.kinematics.lengths_and_jacobian` (eq. 6-7, 15-24),
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


def _compose_exp(pose: Pose, d: list[float]) -> Pose:
    """``pose · exp(d)`` for a twist d = [v, ω] in the platform frame, in scalar arithmetic.

    The same map as :func:`cdpr_twin.se3.se3_exp` (Rodrigues and its left Jacobian).
    """
    vx, vy, vz, wx, wy, wz = d
    th2 = wx * wx + wy * wy + wz * wz
    a, b, c = exp_coefficients(th2)
    # dR = I + a[ω]× + b[ω]×², V = I + b[ω]× + c[ω]×², with [ω]×² = ωωᵀ − θ² I
    xx, yy, zz, xy, xz, yz = wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz
    d00, d11, d22 = 1.0 + b * (xx - th2), 1.0 + b * (yy - th2), 1.0 + b * (zz - th2)
    d01, d10 = b * xy - a * wz, b * xy + a * wz
    d02, d20 = b * xz + a * wy, b * xz - a * wy
    d12, d21 = b * yz - a * wx, b * yz + a * wx
    px = (1.0 + c * (xx - th2)) * vx + (c * xy - b * wz) * vy + (c * xz + b * wy) * vz
    py = (c * xy + b * wz) * vx + (1.0 + c * (yy - th2)) * vy + (c * yz - b * wx) * vz
    pz = (c * xz - b * wy) * vx + (c * yz + b * wx) * vy + (1.0 + c * (zz - th2)) * vz
    r00, r01, r02, r10, r11, r12, r20, r21, r22, t0, t1, t2 = pose
    return (
        r00 * d00 + r01 * d10 + r02 * d20, r00 * d01 + r01 * d11 + r02 * d21,
        r00 * d02 + r01 * d12 + r02 * d22,
        r10 * d00 + r11 * d10 + r12 * d20, r10 * d01 + r11 * d11 + r12 * d21,
        r10 * d02 + r11 * d12 + r12 * d22,
        r20 * d00 + r21 * d10 + r22 * d20, r20 * d01 + r21 * d11 + r22 * d21,
        r20 * d02 + r21 * d12 + r22 * d22,
        t0 + r00 * px + r01 * py + r02 * pz,
        t1 + r10 * px + r11 * py + r12 * pz,
        t2 + r20 * px + r21 * py + r22 * pz,
    )  # fmt: skip


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
) -> tuple[np.ndarray, float, int]:
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
        ``(T, residual, iterations)`` with residual = max |lengths(T) − targets| [m].
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
) -> tuple[np.ndarray, float, int]:
    pose: Pose = tuple(T0[:3].ravel().tolist()[i] for i in _POSE_IDX)
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
    p = pose
    T = np.array(
        [
            [p[0], p[1], p[2], p[9]],
            [p[3], p[4], p[5], p[10]],
            [p[6], p[7], p[8], p[11]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    return T, max(map(abs, r)), it


def solve_scipy(
    a_base: np.ndarray,
    b_platform: np.ndarray,
    pulley_radius: np.ndarray | None,
    targets: np.ndarray,
    T0: np.ndarray,
    x0: np.ndarray | None = None,
) -> tuple[np.ndarray, float, int]:
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
    return T, float(np.max(np.abs(sol.fun[:N_USED]))), int(sol.nfev)


@dataclass(frozen=True)
class ModelOptions:
    """Options of the model-based estimators (Algorithm 1).

    Attributes:
        backend: ``"fast"`` (Newton on SE(3)) or ``"scipy"`` (the paper's formulation).
        taut_threshold: a cable counts as taut above this tension [N]; with fewer than six
            taut cables the estimate is held and flagged (the six would include slack ones).
        tension0: τ(0) of eq. 13, the tension at which the encoders read unstretched lengths [N].
        max_residual: the solve is accepted when every used length matches within this [m].
    """

    backend: Literal["fast", "scipy"] = option("fast")
    taut_threshold: float = option(1.0, minimum=0.0, unit="N")
    tension0: float = option(0.0, unit="N")
    max_residual: float = option(1e-9, minimum=1e-15, unit="m")

    def __post_init__(self) -> None:
        if self.backend not in ("fast", "scipy"):
            raise OptionError("backend", f"must be 'fast' or 'scipy', got {self.backend!r}")
        for name, low in (("taut_threshold", 0.0), ("max_residual", 1e-15)):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= low):
                raise OptionError(name, f"must be a finite number ≥ {low}, got {value}")
        if not math.isfinite(self.tension0):
            raise OptionError("tension0", f"must be finite, got {self.tension0}")


class ModelEstimator(Estimator):
    """Algorithm 1: least squares on the six most-tensioned cables, warm-started.

    Args:
        geometry: nominal geometry.
        options: :class:`ModelOptions`.
    """

    Options = ModelOptions
    elastic: ClassVar[bool] = False
    pulley: ClassVar[bool] = False

    def __init__(self, geometry: CdprGeometry, options: ModelOptions | None = None) -> None:
        super().__init__(geometry, options)
        o = self.options
        self.backend: Backend = o.backend
        self.taut_threshold = float(o.taut_threshold)
        self.tension0 = float(o.tension0)
        self.max_residual = float(o.max_residual)
        radii = geometry.pulley_radius if self.pulley else None
        self._cables = _cable_tuples(geometry.a_base, geometry.b_platform, radii)

    def corrected_lengths(self, lengths: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """Encoder lengths, plus the stretch of eq. 14 in the elastic variants. (m,) [m]."""
        if not self.elastic:
            return lengths
        return lengths + elastic_elongation(lengths, tensions, self.geometry.es, self.tension0)

    def solve(self, targets: np.ndarray, cables: list[int], T0: np.ndarray):
        """Solve for the pose matching ``targets`` on ``cables`` (indices from 0) from ``T0``.

        Returns:
            ``(T, residual, iterations)``.
        """
        if self.backend == "fast":
            goal = [targets[i] for i in cables] if isinstance(targets, list) else targets[cables]
            return _newton([self._cables[i] for i in cables], self.pulley, goal, T0)
        cables = np.asarray(cables)
        g = self.geometry
        r = g.pulley_radius[cables] if self.pulley else None
        return solve_scipy(g.a_base[cables], g.b_platform[cables], r, targets[cables], T0)

    def update(
        self, measurement: Measurement, inputs: Mapping[str, PoseEstimate] = NO_INPUTS
    ) -> PoseEstimate:
        """One pass of Algorithm 1's loop (lines 7-12)."""
        self._check_reset()
        m = measurement
        if (held := self._bad_time(m)) is not None:
            return held
        watch = self._encoder_flags(m, tensions=True)
        lengths, tensions = m.cable_lengths, m.tensions
        if not math.isfinite(float(lengths.sum() + tensions.sum())):  # NaN/inf propagate
            return self._held(m, NON_FINITE_INPUT)
        tl = tensions.tolist()
        order = sorted(range(len(tl)), key=tl.__getitem__, reverse=True)  # line 8
        cables = sorted(order[:N_USED])
        used = tuple(cables)
        if sum(t > self.taut_threshold for t in tl) < N_USED:
            return self._held(m, FEW_TAUT_CABLES, cables=used)
        targets = self.corrected_lengths(lengths, tensions)
        T, residual, iterations = self.solve(targets, cables, self._T)
        if not (residual <= self.max_residual and math.isfinite(T.sum())):
            return self._held(
                m, NOT_CONVERGED, cables=used, residual=residual, iterations=iterations
            )
        self._T = T
        self._time = m.time
        return PoseEstimate(
            m.time, T, flags=watch, cables=used, residual=residual, iterations=iterations
        )


@register
class SimpleModelEstimator(ModelEstimator):
    """Est. 3: massless, inextensible, straight cables from A_i to B_i."""

    name = "model_simple"


@register
class ElasticModelEstimator(ModelEstimator):
    """Est. 4: straight cables, lengths corrected for elastic stretch (eq. 13-14)."""

    name = "model_elastic"
    elastic = True


@register
class PulleyModelEstimator(ModelEstimator):
    """Est. 5: inextensible cables over swivelling pulleys (eq. 15-24)."""

    name = "model_pulley"
    pulley = True


@register
class ElasticPulleyModelEstimator(ModelEstimator):
    """Est. 6: pulleys and stretch together (eq. 25)."""

    name = "model_elastic_pulley"
    elastic = True
    pulley = True
