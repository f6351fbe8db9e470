"""Levenberg–Marquardt on the normal equations of a sparse least-squares problem (numpy, scipy).

A calibration has a few hundred to a few thousand unknowns (six per recorded pose) and a few
times more residuals; its Jacobian is sparse (each pose's residuals see only that pose and the
shared parameters). ``scipy.optimize.least_squares`` offers dense exact trust-region steps (an
SVD of the whole Jacobian per iteration: O(rows · n²), minutes at 240 poses) or iterative LSMR
steps (which stall on this problem's conditioning). Here each step solves the damped normal
equations (JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr by a Cholesky factorisation of the n × n matrix
(O(n³/3), a fraction of a second at n = 1 500) — or, told how many unknowns are shared, by
eliminating the poses' 6 × 6 blocks (:mod:`cdpr_twin.calibrate.schur`) —, with Marquardt's
scaling and Nielsen's update of λ (Madsen, Nielsen, Tingleff, *Methods for Non-Linear Least
Squares Problems*, 2004, §3.2).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.sparse import csc_matrix

from cdpr_twin.calibrate.schur import Arrow, arrow, damped_step, inverse_parts


@dataclass(frozen=True, eq=False)
class Solution:
    """Where the iterations stopped.

    Attributes:
        x: (n,) the parameters.
        fun: (n_rows,) the residuals there.
        jac: (n_rows, n) sparse Jacobian there.
        cost: ½ rᵀr.
        nfev: residual evaluations (Jacobians included).
        iterations: accepted and rejected steps.
        converged: a stopping test held (not the iteration limit).
        message: which one.
    """

    x: np.ndarray
    fun: np.ndarray
    jac: csc_matrix
    cost: float
    nfev: int
    iterations: int
    converged: bool
    message: str


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], tuple[csc_matrix, int]],
    x0: np.ndarray,
    max_iterations: int = 100,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    lam0: float = 1e-3,
    shrink: float = 1.0 / 3.0,
    n_shared: int | None = None,
) -> Solution:
    """Minimise ½‖fun(x)‖² from ``x0``.

    Args:
        fun: residuals, (n,) → (n_rows,).
        jac: Jacobian at x, (n,) → ((n_rows, n) sparse, residual evaluations it took).
        x0: (n,) start.
        max_iterations: most steps (accepted or not).
        ftol: stop when a step lowers the cost by less than ``ftol`` × cost.
        xtol: stop when ‖δ‖ < ``xtol`` · (‖x‖ + xtol), norms in Marquardt's scaling.
        lam0: the damping λ to start from (Marquardt's scaling): small where the first
            steps should be Gauss–Newton's (``x0`` near the minimum, nearly linear residuals).
        shrink: the most λ shrinks by after a step (Nielsen's rule).
        n_shared: the first ``n_shared`` unknowns are shared and the rest come in blocks of
            six that no residual couples (poses): steps by the Schur complement. None, or
            a Jacobian without that shape: a dense factorisation.

    Returns:
        The solution (``converged`` False at the iteration limit).
    """
    x = np.asarray(x0, dtype=float).copy()
    r = fun(x)
    nfev, cost = 1, 0.5 * float(r @ r)
    J, n = jac(x)
    nfev += n
    N, g = _normal(J, r, n_shared)
    lam, nu = lam0, 2.0  # with Marquardt's scaling λ is dimensionless
    for it in range(1, max_iterations + 1):
        d = np.maximum(_diagonal(N), 1e-300)
        step = _damped_step(N, g, lam * d)
        if step is None:  # not positive definite at this damping: damp more
            lam, nu = lam * nu, 2.0 * nu
            continue
        scale = np.sqrt(d)
        if np.linalg.norm(scale * step) < xtol * (np.linalg.norm(scale * x) + xtol):
            return Solution(x, r, J, cost, nfev, it, True, "the step is below xtol")
        r_new = fun(x + step)
        nfev += 1
        cost_new = 0.5 * float(r_new @ r_new)
        predicted = 0.5 * float(step @ (lam * d * step - g))  # the linear model's decrease
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if not np.isfinite(cost_new) or rho <= 0:  # worse (or not finite): reject, damp more
            lam, nu = lam * nu, 2.0 * nu
            continue
        x, r, decrease, cost = x + step, r_new, cost - cost_new, cost_new
        if decrease < ftol * cost:
            J, n = jac(x)
            return Solution(x, r, J, cost, nfev + n, it, True, "the cost decrease is below ftol")
        J, n = jac(x)
        nfev += n
        N, g = _normal(J, r, n_shared)
        lam *= max(shrink, 1.0 - (2.0 * rho - 1.0) ** 3)
        nu = 2.0
    return Solution(x, r, J, cost, nfev, max_iterations, False, "the iteration limit was hit")


def _normal(J: csc_matrix, r: np.ndarray, n_shared: int | None = None) -> tuple:
    """JᵀJ (dense, n × n; by its blocks if it is an arrow with ``n_shared``) and Jᵀr."""
    Jt = J.T.tocsr()
    N = (Jt @ J).toarray()
    blocks = None if n_shared is None else arrow(N, n_shared)
    return (N if blocks is None else blocks), Jt @ r


def _diagonal(N: np.ndarray | Arrow) -> np.ndarray:
    if isinstance(N, Arrow):
        return np.concatenate([np.diag(N.A), np.einsum("kii->ki", N.D).ravel()])
    return np.diag(N)


def _damped_step(N: np.ndarray | Arrow, g: np.ndarray, damping: np.ndarray) -> np.ndarray | None:
    """δ solving (N + diag(damping)) δ = −g, or ``None`` if that matrix is not PD."""
    if isinstance(N, Arrow):
        return damped_step(N, g, damping)
    A = N + np.diag(damping)
    try:
        return -cho_solve(cho_factor(A, lower=True, check_finite=False), g, check_finite=False)
    except LinAlgError:
        return None


def shared_covariance(J: csc_matrix, n_shared: int, s2: float) -> np.ndarray:
    """Covariance of the first ``n_shared`` parameters, s² · [(JᵀJ)⁻¹]ₛₛ.

    Solved for those columns only (Cholesky), with a pseudo-inverse fallback where JᵀJ is
    singular (a parameter no residual sees). Returns (n_shared, n_shared).
    """
    N = (J.T.tocsr() @ J).toarray()
    blocks = arrow(N, n_shared)
    parts = None if blocks is None else inverse_parts(blocks)
    if parts is not None and parts.S_inv is not None:
        return s2 * parts.S_inv
    E = np.zeros((N.shape[0], n_shared))
    E[np.arange(n_shared), np.arange(n_shared)] = 1.0
    try:
        X = cho_solve(cho_factor(N, lower=True, check_finite=False), E, check_finite=False)
    except LinAlgError:
        X = np.linalg.pinv(N) @ E
    return s2 * X[:n_shared]
