"""Normal equations of shared unknowns and per-pose blocks, by the Schur complement (scipy).

A calibration's residuals each see the shared parameters and at most one pose's six, so its
normal matrix is an arrow: N = [[A, Cᵀ], [C, D]], with D block-diagonal (a 6 × 6 block per
pose). Eliminating the poses leaves the shared parameters' Schur complement
S = A − Cᵀ D⁻¹ C (n_s × n_s, ≈ 100 on ACROBOT): a damped step, the shared parameters'
covariance (S⁻¹) and each residual's leverage cost O(K · 6² · n_s + n_s³) instead of the
O((n_s + 6K)³) of a dense factorisation (n = 1 550 at 240 poses: a Cholesky of 0.07 s per
step). Triggs et al., *Bundle Adjustment — A Modern Synthesis*, 2000, §6.1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.sparse import csc_matrix


@dataclass(frozen=True, eq=False)
class Arrow:
    """An arrow-shaped normal matrix by its blocks.

    Attributes:
        A: (n_s, n_s) shared × shared.
        C: (K, 6, n_s) each pose × shared.
        D: (K, 6, 6) each pose's own block.
    """

    A: np.ndarray
    C: np.ndarray
    D: np.ndarray

    @property
    def n_shared(self) -> int:
        """n_s."""
        return self.A.shape[0]


def arrow(N: np.ndarray, n_shared: int) -> Arrow | None:
    """The blocks of a dense normal matrix ``N`` (n, n); None if it is not an arrow.

    Not an arrow: fewer than one pose, a size that is not n_shared + 6K, or any entry coupling
    two poses.
    """
    s, n = n_shared, N.shape[0]
    K = (n - s) // 6
    if K < 1 or n != s + 6 * K:
        return None
    P = N[s:, s:].reshape(K, 6, K, 6)
    k = np.arange(K)
    D = P[k, :, k, :].copy()  # (K, 6, 6)
    P = P.copy()
    P[k, :, k, :] = 0.0
    if np.any(P):
        return None
    return Arrow(N[:s, :s], N[s:, :s].reshape(K, 6, s), D)


@dataclass(frozen=True, eq=False)
class Elimination:
    """The pose blocks eliminated from a damped arrow matrix.

    Attributes:
        D_inv: (K, 6, 6) the damped pose blocks' inverses.
        X: (K, 6, n_s) D_k⁻¹ C_k.
        factor: the Schur complement's Cholesky factor (``scipy.linalg.cho_factor``), or
            ``None`` without shared unknowns.
    """

    D_inv: np.ndarray
    X: np.ndarray
    factor: tuple | None


@dataclass(frozen=True, eq=False)
class ArrowInverse:
    """What N⁻¹ of an arrow matrix is made of (its pose blocks are D⁻¹ + X S⁻¹ Xᵀ).

    Attributes:
        S_inv: (n_s, n_s) N⁻¹'s shared block, or ``None`` without shared unknowns.
        X: (K, 6, n_s) D_k⁻¹ C_k.
        D_inv: (K, 6, 6) the pose blocks' inverses.
    """

    S_inv: np.ndarray | None
    X: np.ndarray
    D_inv: np.ndarray


def _eliminate(a: Arrow, damping: np.ndarray) -> Elimination | None:
    """The damped D's blocks' inverses, X_k = D_k⁻¹ C_k and the factorised Schur complement.

    None where the damped matrix is not positive definite.
    """
    s, K = a.n_shared, len(a.D)
    D = a.D + damping[s:].reshape(K, 6)[:, :, None] * np.eye(6)
    try:
        np.linalg.cholesky(D)  # positive definite blocks, or LinAlgError
        D_inv = np.linalg.inv(D)
        X = D_inv @ a.C  # (K, 6, s)
        S = a.A + np.diag(damping[:s]) - np.einsum("kis,kit->st", a.C, X)
        factor = cho_factor(S, lower=True, check_finite=False) if s else None
    except LinAlgError:
        return None
    return Elimination(D_inv, X, factor)


def damped_step(a: Arrow, g: np.ndarray, damping: np.ndarray) -> np.ndarray | None:
    """δ solving (N + diag(damping)) δ = −g; None if that matrix is not positive definite."""
    e = _eliminate(a, damping)
    if e is None:
        return None
    D_inv, X = e.D_inv, e.X
    s, K = a.n_shared, len(a.D)
    g_s, g_p = g[:s], g[s:].reshape(K, 6)
    y = np.einsum("kij,kj->ki", D_inv, g_p)  # D⁻¹ g_p
    d_s = np.zeros(0)
    if s:
        d_s = cho_solve(e.factor, g_s - np.einsum("kis,ki->s", a.C, y), check_finite=False)
    d_p = y - np.einsum("kis,s->ki", X, d_s)
    return -np.concatenate([d_s, d_p.ravel()])


def inverse_parts(a: Arrow) -> ArrowInverse | None:
    """What N⁻¹ is made of; None if N is not positive definite."""
    e = _eliminate(a, np.zeros(a.n_shared + 6 * len(a.D)))
    if e is None:
        return None
    n_s = a.n_shared
    S_inv = cho_solve(e.factor, np.eye(n_s), check_finite=False) if n_s else None
    return ArrowInverse(S_inv, e.X, e.D_inv)


def leverages(J: csc_matrix, n_shared: int, parts: ArrowInverse) -> np.ndarray:
    """Each row's J_j N⁻¹ J_jᵀ, N = JᵀJ, from :func:`inverse_parts`. Returns (n_rows,).

    A row with shared part a and pose-k part p: (a − X_kᵀ p)ᵀ S⁻¹ (a − X_kᵀ p) + pᵀ D_k⁻¹ p.
    """
    S_inv, X, D_inv = parts.S_inv, parts.X, parts.D_inv
    J = csc_matrix(J, copy=True)
    J.eliminate_zeros()  # a stored zero must not name another pose
    a = J[:, :n_shared].toarray()
    pose = J[:, n_shared:].tocoo()
    p = np.zeros((J.shape[0], 6))
    k = np.zeros(J.shape[0], dtype=int)
    p[pose.row, pose.col % 6] = pose.data
    k[pose.row] = pose.col // 6
    own = np.einsum("ri,rij,rj->r", p, D_inv[k], p)
    if S_inv is None:  # no shared parameters
        return own
    v = a - np.einsum("ris,ri->rs", X[k], p)
    return np.einsum("rs,rs->r", v @ S_inv, v) + own
