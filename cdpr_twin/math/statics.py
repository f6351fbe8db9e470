"""Static tension distribution of a suspended CDPR (numpy + scipy).

For a pose, find cable tensions τ with Aᵀ τ = w_g (the cables hold the platform's weight;
A is the base-frame Jacobian, so −Aᵀ τ is the cables' wrench on the platform) and
τ_min ≤ τ ≤ τ_max. Among the feasible ones, take the minimum-norm distribution.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog, minimize

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import CableModel, gravity_wrench, jacobian


class InfeasibleTensionError(ValueError):
    """No tension distribution within the bounds holds the platform at the requested pose."""


def tension_distribution(
    geom: CdprGeometry,
    T_base_platform: np.ndarray,
    tau_min: float = 2.0,
    tau_max: float = 75.0,
    model: CableModel = "pulley",
) -> np.ndarray:
    """Minimum-norm cable tensions holding the platform static at a pose.

    Args:
        geom: CDPR geometry.
        T_base_platform: (4, 4) platform pose.
        tau_min: lowest admissible tension [N] (> 0 keeps every cable taut).
        tau_max: highest admissible tension [N] (ACROBOT's sensors read up to 75 N).
        model: cable model for the cable directions (``"pulley"`` is exact for the twin).

    Returns:
        (m,) tensions [N].

    Raises:
        InfeasibleTensionError: when no distribution within [tau_min, tau_max] exists.
    """
    if not 0.0 <= tau_min < tau_max:
        raise ValueError(f"need 0 ≤ tau_min < tau_max, got tau_min={tau_min}, tau_max={tau_max}")
    W = jacobian(geom, T_base_platform, "base", model).T  # (6, m)
    rhs = gravity_wrench(geom, T_base_platform)  # cables' wrench −Aᵀτ cancels w_g
    m = geom.n_cables
    lp = linprog(np.ones(m), A_eq=W, b_eq=rhs, bounds=[(tau_min, tau_max)] * m, method="highs")
    if lp.status != 0:
        raise InfeasibleTensionError(
            f"no tension distribution with {tau_min} N ≤ τ ≤ {tau_max} N holds the platform at "
            f"position {np.round(T_base_platform[:3, 3], 4).tolist()} m (linprog: {lp.message}); "
            "choose a pose nearer the workspace centre or widen the tension bounds"
        )
    return _minimum_norm(W, rhs, lp.x, tau_min, tau_max)


def _minimum_norm(
    W: np.ndarray, rhs: np.ndarray, x0: np.ndarray, tau_min: float, tau_max: float
) -> np.ndarray:
    """The least-norm τ with W τ = rhs within the bounds, from a feasible vertex x0."""
    # Minimum norm on the null space: τ = x0 + N λ.
    _, s, vt = np.linalg.svd(W)
    rank = int(np.sum(s > s[0] * 1e-12))
    N = vt[rank:].T
    if N.shape[1] == 0:
        return x0
    res = minimize(
        lambda lam: float(np.sum((x0 + N @ lam) ** 2)),
        np.zeros(N.shape[1]),
        jac=lambda lam: 2.0 * N.T @ (x0 + N @ lam),
        constraints=[
            {"type": "ineq", "fun": lambda lam: x0 + N @ lam - tau_min, "jac": lambda lam: N},
            {"type": "ineq", "fun": lambda lam: tau_max - x0 - N @ lam, "jac": lambda lam: -N},
        ],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 200},
    )
    # SLSQP may stop at the optimum yet report failure (status 8, "positive directional
    # derivative"): keep its answer whenever it is feasible and better than the LP vertex.
    tau = x0 + N @ res.x
    feasible = np.all(tau >= tau_min - 1e-9) and np.all(tau <= tau_max + 1e-9)
    if not (np.all(np.isfinite(tau)) and feasible and tau @ tau <= x0 @ x0):
        tau = x0
    tau = np.clip(tau, tau_min, tau_max)
    # Project back onto W τ = rhs (removes the SLSQP/clip residue, stays inside the bounds
    # to within round-off because the correction is tiny).
    tau += np.linalg.lstsq(W, rhs - W @ tau, rcond=None)[0]
    return tau
