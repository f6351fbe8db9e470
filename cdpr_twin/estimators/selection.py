"""Which cables the model-based estimators use, and how much each one is trusted (numpy only).

Algorithm 1 of the paper solves on the six most-tensioned cables. Near configurations where
those six form a nearly singular set (a slack-prone cable among them, or tensions swinging at a
servo's start) the solve jumps: its Jacobian's condition number reaches 10³-10⁴ against ≈ 19
elsewhere. The alternatives here avoid such sets, and hold the estimate (flag
``ill_conditioned``) when no well-conditioned set is taut:

- ``"best_conditioned"``: among the taut cables, the six whose platform-frame Jacobian (eq. 6,
  at the last estimate) has the smallest condition number; ties go to the larger total tension;
- ``"all_taut"``: every taut cable, in weighted least squares with weights 1/σ_i² from the
  encoder noise, the tension noise mapped through the cable's elasticity (δl = l·δτ/E·S, eq. 14)
  and, in the variants that neglect stretch, the stretch itself.
"""

from __future__ import annotations

from itertools import combinations
from typing import Literal

import numpy as np

Selection = Literal["most_tensioned", "best_conditioned", "all_taut"]
SELECTIONS = ("most_tensioned", "best_conditioned", "all_taut")
N_USED = 6
"""Cables in a square solve (the platform's six degrees of freedom)."""


def most_tensioned(tensions: list[float], n: int = N_USED) -> list[int]:
    """Indices (from 0, sorted) of the ``n`` largest tensions (Algorithm 1, line 8)."""
    order = sorted(range(len(tensions)), key=tensions.__getitem__, reverse=True)
    return sorted(order[:n])


def best_conditioned(rows: np.ndarray, tensions: np.ndarray, taut: np.ndarray) -> list[int]:
    """The six taut cables whose Jacobian rows form the best-conditioned set.

    Args:
        rows: (m, 6) platform-frame Jacobian rows of every cable at the current estimate.
        tensions: (m,) measured tensions [N] (ties: the larger total tension wins).
        taut: (m,) bool, the cables above the taut threshold (at least six).

    Returns:
        Six indices (from 0), sorted.
    """
    candidates = [list(c) for c in combinations(np.asarray(taut).nonzero()[0].tolist(), N_USED)]
    sv = np.linalg.svd(rows[np.array(candidates)], compute_uv=False)  # (k, 6), descending
    with np.errstate(divide="ignore"):
        cond = sv[:, 0] / sv[:, -1]
    total = tensions[np.array(candidates)].sum(axis=1)
    best = min(range(len(candidates)), key=lambda j: (cond[j], -total[j]))
    return candidates[best]


def condition_number(rows: np.ndarray) -> float:
    """Condition number σ_max/σ_min of a (k, 6) Jacobian, k ≥ 6 (∞ when rank-deficient)."""
    sv = np.linalg.svd(rows, compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def length_sigma(
    lengths: np.ndarray,
    tensions: np.ndarray,
    es: np.ndarray,
    length_noise_std: float,
    tension_noise_std: float,
    elastic: bool,
) -> np.ndarray:
    """Standard deviation of each cable's model-length residual [m], for weighting.

    σ_i² = σ_enc² + (l_i σ_τ / E·S_i)² (+ (l_i τ_i / E·S_i)² when the stretch is neglected).

    Args:
        lengths: (m,) encoder lengths [m].
        tensions: (m,) measured tensions [N].
        es: (m,) nominal E·S [N].
        length_noise_std: encoder noise std [m].
        tension_noise_std: tension-reading error std [N].
        elastic: whether the stretch is corrected (eq. 14); if not it counts as an error.

    Returns:
        (m,) σ_i [m].
    """
    compliance = lengths / es  # [m/N]
    var = length_noise_std**2 + (compliance * tension_noise_std) ** 2
    if not elastic:
        var = var + (compliance * tensions) ** 2
    return np.sqrt(var)
