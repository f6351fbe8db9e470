"""The model-based estimators' Newton solve on SE(3) (Algorithm 1), compiled with Numba.

:func:`cdpr_twin.estimators.solvers._newton` (scalar Python: the reference) spends 55–65 µs
of a model-based update in a few dozen Python-level calls; here the whole solve is one compiled
call. It performs the same floating-point operations in the same order — the kernel of
:func:`cdpr_twin.estimators.fused_kernels.kernel`, the scalar ``pose · exp(δ)`` of
``solvers._compose_exp``, LAPACK's ``dgesv`` from the same SciPy library, sums left to
right — so its poses equal the reference's bit for bit (``tests/test_newton.py``; the golden
runs of ``tests/test_golden.py`` compare every CSV cell byte for byte).

Where the reference leaves its main path (a singular or non-finite system, where it takes
NumPy's least-squares step or stops), this solve says so and the caller runs the reference
instead, from the start: the two then agree by construction. Compiled on first use, cached on
disk like the fused filter's kernels (:mod:`cdpr_twin.estimators.fused_core`).
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.estimators.fused_kernels import exp_coefficients, jit, kernel

MAIN, FALLBACK = 0, 1
"""Outcomes of :func:`newton`: solved on the main path, or the reference must solve."""


@jit
def compose_exp(T: np.ndarray, d0, d1, d2, d3, d4, d5) -> np.ndarray:
    """``T · exp(d)``, d = [v, ω] in the platform frame: ``solvers._compose_exp``'s operations."""
    vx, vy, vz, wx, wy, wz = d0, d1, d2, d3, d4, d5
    th2 = wx * wx + wy * wy + wz * wz
    a, b, c = exp_coefficients(th2)
    xx, yy, zz, xy, xz, yz = wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz
    d00, d11, d22 = 1.0 + b * (xx - th2), 1.0 + b * (yy - th2), 1.0 + b * (zz - th2)
    d01, d10 = b * xy - a * wz, b * xy + a * wz
    d02, d20 = b * xz + a * wy, b * xz - a * wy
    d12, d21 = b * yz - a * wx, b * yz + a * wx
    px = (1.0 + c * (xx - th2)) * vx + (c * xy - b * wz) * vy + (c * xz + b * wy) * vz
    py = (c * xy + b * wz) * vx + (1.0 + c * (yy - th2)) * vy + (c * yz - b * wx) * vz
    pz = (c * xz - b * wy) * vx + (c * yz + b * wx) * vy + (1.0 + c * (zz - th2)) * vz
    out = np.zeros((4, 4))
    for i in range(3):
        ri0, ri1, ri2 = T[i, 0], T[i, 1], T[i, 2]
        out[i, 0] = ri0 * d00 + ri1 * d10 + ri2 * d20
        out[i, 1] = ri0 * d01 + ri1 * d11 + ri2 * d21
        out[i, 2] = ri0 * d02 + ri1 * d12 + ri2 * d22
        out[i, 3] = T[i, 3] + ri0 * px + ri1 * py + ri2 * pz
    out[3, 3] = 1.0
    return out


@jit
def _residuals(cables: np.ndarray, T: np.ndarray, goal: np.ndarray):
    """Lengths(T) − goal, their squared sum (left to right) and the Jacobian rows."""
    lengths, rows = kernel(cables, T)
    r = lengths - goal
    cost = 0.0
    for i in range(r.shape[0]):
        cost += r[i] * r[i]
    return r, cost, rows


@jit
def _largest(r: np.ndarray) -> float:
    """``max(map(abs, r))`` as Python evaluates it (a NaN first stays; a later one is passed)."""
    out = abs(r[0])
    for i in range(1, r.shape[0]):
        if abs(r[i]) > out:
            out = abs(r[i])
    return out


@jit
def newton(cables: np.ndarray, goal: np.ndarray, T0: np.ndarray, max_iterations: int, tol: float):
    """Newton solve of lengths(T) = goal from T0: ``solvers._newton``'s main path.

    Args:
        cables: (6, 7) the cables used, as :func:`~cdpr_twin.estimators.fused_kernels.kernel`
            takes them (sheave radius 0: a point exit).
        goal: (6,) target lengths [m].
        T0: (4, 4) initial guess.
        max_iterations: iteration cap.
        tol: stop when every residual is below this [m].

    Returns:
        ``(T, residual, iterations, outcome)``: residual = max |lengths(T) − goal| [m];
        ``outcome`` :data:`FALLBACK` when the reference must solve instead (T then unset).
    """
    T = T0.copy()
    r, cost, rows = _residuals(cables, T, goal)
    it = 0
    while it < max_iterations and _largest(r) > tol:
        it += 1
        try:  # LAPACK's dgesv; it raises on a singular or non-finite system
            x = np.linalg.solve(rows, -r)
        except Exception:  # Numba catches no narrower class
            return T, 0.0, it, FALLBACK
        sq = 0.0
        for i in range(6):
            sq += x[i] * x[i]
        if not math.isfinite(sq):
            return T, 0.0, it, FALLBACK
        step = 1.0
        decreased = False
        for _ in range(30):  # step halving keeps the cost decreasing far from the root
            T_new = compose_exp(
                T, step * x[0], step * x[1], step * x[2], step * x[3], step * x[4], step * x[5]
            )
            r_new, cost_new, rows_new = _residuals(cables, T_new, goal)
            if cost_new <= cost:
                decreased = True
                break
            step *= 0.5
        if not decreased:
            break
        T, rows, r, cost = T_new, rows_new, r_new, cost_new
    return T, _largest(r), it, MAIN


def warm_up() -> None:
    """Compile (or load from the disk cache) :func:`newton` before the first update."""
    cables = np.array([[1.0, 0, 0, 0, 0, 0, 0.0], [0, 1, 0, 0, 0, 0, 0.0]] * 3)
    newton(cables, np.ones(6), np.eye(4), 1, 1e-12)
