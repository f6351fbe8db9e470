"""Finite-difference Jacobians of a calibration's residuals that use their sparsity (numpy, scipy).

Central differences; the columns are perturbed in groups whose residuals do not overlap, so
a Jacobian costs two evaluations per group instead of two per parameter.

- :func:`grouped_jacobian`: groups over the whole residual vector — each shared parameter
  alone, and the k-th parameter of every pose together (pose k's parameters reach only pose
  k's residuals): 2 · (n_shared + 6) evaluations of every residual.
- :class:`PartJacobian`: the residuals in parts (cables, tags, wrench balances, priors), each
  differentiated with its own groups. A cable's exit point reaches only that cable's length
  residuals, so within the cable part the eight cables' exit points share a group; only the
  wrench balances see every cable at once. About 3× fewer residual rows evaluated than
  :func:`grouped_jacobian` on ACROBOT's recordings, same values up to rounding. A part may
  give some of its columns itself, vectorised (the tag views over camera, tag and intrinsics
  at once, :func:`cdpr_twin.calibrate.tag_views.view_jacobian`; the wrench balance one cable's term
  at a time, :func:`cdpr_twin.calibrate.wrench_balance.cable_jacobian`); the groups cover the rest.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csc_matrix


def grouped_jacobian(
    fun, x: np.ndarray, pattern: csc_matrix, n_shared: int, h: float = 1e-6
) -> tuple[csc_matrix, int]:
    """Central differences, one pair of evaluations of every residual per group.

    Args:
        fun: the residuals, x (n,) → (n_rows,).
        x: (n,) where to differentiate.
        pattern: (n_rows, n) sparsity pattern (CSC).
        n_shared: number of shared parameters (the first ones).
        h: step [m or rad].

    Returns:
        The (n_rows, n) Jacobian on the pattern (CSC), and the evaluations it took.
    """
    n = len(x)
    groups = [[j] for j in range(n_shared)]
    groups += [list(range(n_shared + j, n, 6)) for j in range(6)]
    data, rows = np.zeros(pattern.nnz), slice(0, pattern.shape[0])
    for cols in groups:
        at, r = _where(pattern, cols, rows)
        data[at] = _differentiate(fun, x, cols, h)[r]
    J = csc_matrix((data, pattern.indices, pattern.indptr), shape=pattern.shape)
    return J, 2 * len(groups)


def _differentiate(fun, x: np.ndarray, cols: list[int], h: float) -> np.ndarray:
    """Central differences of ``fun`` moving the columns ``cols`` together (rows disjoint)."""
    dx = np.zeros(len(x))
    dx[cols] = h
    return (fun(x + dx) - fun(x - dx)) / (2.0 * h)


def _where(pattern: csc_matrix, cols: list[int], rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """Where columns ``cols`` have entries in ``rows``: positions in ``pattern.data``, rows.

    The rows are counted from ``rows.start``.
    """
    at = np.concatenate(
        [np.arange(pattern.indptr[c], pattern.indptr[c + 1]) for c in cols] or [np.zeros(0)]
    )
    at = at.astype(np.intp)
    r = pattern.indices[at]
    inside = (r >= rows.start) & (r < rows.stop)
    return at[inside], r[inside] - rows.start


def _colour(block: csc_matrix, skip=()) -> list[list[int]]:
    """Greedy grouping of ``block``'s nonzero columns but ``skip`` into sets of disjoint rows."""
    occupied: list[np.ndarray] = []
    groups: list[list[int]] = []
    for c in np.setdiff1d(np.flatnonzero(np.diff(block.indptr)), np.asarray(skip, dtype=int)):
        rows = block.indices[block.indptr[c] : block.indptr[c + 1]]
        for g, taken in enumerate(occupied):
            if not taken[rows].any():
                taken[rows] = True
                groups[g].append(int(c))
                break
        else:
            taken = np.zeros(block.shape[0], dtype=bool)
            taken[rows] = True
            occupied.append(taken)
            groups.append([int(c)])
    return groups


class PartJacobian:
    """Central differences of residuals given in parts, each part with its own column groups.

    Args:
        parts: per part, its rows (a slice of the whole residual vector), its residuals as a
            function of x (n,) → (rows,), and optionally columns it differentiates itself:
            ``(cols, jac)`` with ``jac(x, h)`` → (rows, len(cols)), dense.
        pattern: (n_rows, n) sparsity pattern of the whole residual vector (CSC).
        h: step [m or rad].
        groups: per part, its column groups, when already computed for this pattern.
    """

    def __init__(
        self,
        parts: list[tuple],
        pattern: csc_matrix,
        h: float = 1e-6,
        groups: list[list[list[int]]] | None = None,
    ) -> None:
        self.parts, self.pattern, self.h = parts, csc_matrix(pattern), h
        given = [part[2][0] if len(part) > 2 else [] for part in parts]
        self.groups = groups or [
            _colour(self.pattern[part[0]], cols) for part, cols in zip(parts, given, strict=True)
        ]
        # per part and group: where its derivatives go in the pattern's data, and which of
        # the part's rows they are; the columns a part gives, likewise, one by one
        self._scatter = [
            [_where(self.pattern, cols, part[0]) for cols in part_groups]
            for part, part_groups in zip(parts, self.groups, strict=True)
        ]
        self._given = [
            [_where(self.pattern, [c], part[0]) for c in cols]
            for part, cols in zip(parts, given, strict=True)
        ]

    @property
    def evaluations(self) -> int:
        """Part evaluations per Jacobian (each one residual evaluation; given columns: a pair)."""
        return 2 * sum(len(g) for g in self.groups) + 2 * sum(map(bool, self._given))

    def __call__(self, x: np.ndarray) -> tuple[csc_matrix, int]:
        """The (n_rows, n) Jacobian at ``x`` (CSC, on the pattern), and the evaluations."""
        p = self.pattern
        data = np.zeros(p.nnz)
        for part, groups, scatter, given in zip(
            self.parts, self.groups, self._scatter, self._given, strict=True
        ):
            for cols, (at, rows) in zip(groups, scatter, strict=True):
                data[at] = _differentiate(part[1], x, cols, self.h)[rows]
            if given:
                block = part[2][1](x, self.h)
                for j, (at, rows) in enumerate(given):
                    data[at] = block[rows, j]
        J = csc_matrix((data, p.indices, p.indptr), shape=p.shape)
        return J, self.evaluations
