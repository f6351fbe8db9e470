"""The model-based estimators' Newton solve on SE(3) (Algorithm 1), compiled with Numba.

:func:`cdpr_twin.estimators.solvers._newton` (scalar Python: the reference) spends 55–65 µs
of a model-based update in a few dozen Python-level calls; here the whole solve is one compiled
call. It performs the same floating-point operations in the same order — the kernel of
:func:`cdpr_twin.estimators.compiled_kernels.kernel`, the scalar ``pose · exp(δ)`` of
``solvers._compose_exp``, LAPACK's ``dgesv`` from the same SciPy library, sums left to
right — so its poses equal the reference's bit for bit (``tests/estimators/test_newton.py``;
the golden runs of ``tests/test_golden.py`` compare every CSV cell byte for byte).

Where the reference leaves its main path (a singular or non-finite system, where it takes
NumPy's least-squares step or stops), this solve says so and the caller runs the reference
instead, from the start: the two then agree by construction. Compiled on first use, cached on
disk like the fused filter's kernels (:mod:`cdpr_twin.estimators.fused_core`).
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.estimators import solvers
from cdpr_twin.estimators.compiled_kernels import exp_coefficients, jit, kernel

MAIN, FALLBACK = 0, 1
"""Outcomes of :func:`newton`: solved on the main path, or the reference must solve."""


exp_terms = jit(solvers.exp_terms)
"""``solvers.exp_terms``, compiled: exp(d)'s rotation (9 floats, row-major) and V·v (3)."""


@jit
def compose_exp(T: np.ndarray, d0, d1, d2, d3, d4, d5) -> np.ndarray:
    """``T · exp(d)``, d = [v, ω] in the platform frame: ``solvers._compose_exp``'s operations."""
    th2 = d3 * d3 + d4 * d4 + d5 * d5
    a, b, c = exp_coefficients(th2)
    e = exp_terms(d0, d1, d2, d3, d4, d5, th2, a, b, c)
    out = np.zeros((4, 4))
    for i in range(3):
        ri0, ri1, ri2 = T[i, 0], T[i, 1], T[i, 2]
        out[i, 0] = ri0 * e[0] + ri1 * e[3] + ri2 * e[6]
        out[i, 1] = ri0 * e[1] + ri1 * e[4] + ri2 * e[7]
        out[i, 2] = ri0 * e[2] + ri1 * e[5] + ri2 * e[8]
        out[i, 3] = T[i, 3] + ri0 * e[9] + ri1 * e[10] + ri2 * e[11]
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
        cables: (6, 7) the cables used, as :func:`~cdpr_twin.estimators.compiled_kernels.kernel`
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
    """Compile (or load from the disk cache) :func:`newton` and :func:`compose_exp`.

    Called when an estimator is built, before its first update (as the fused filter's
    :func:`cdpr_twin.estimators.fused_core.warm_up`).
    """
    cables = np.array([[1.0, 0, 0, 0, 0, 0, 0.0], [0, 1, 0, 0, 0, 0, 0.0]] * 3)
    newton(cables, np.ones(6), np.eye(4), 1, 1e-12)
    compose_exp(np.eye(4), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
