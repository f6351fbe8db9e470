"""The wrench balance residuals of a calibration, and their derivatives cable by cable (numpy).

At each pose where every cable is taut, the force Σ τ_i·u_i − m·g and the moment about the
platform's origin Σ ᵇR_p·b_i × (−τ_i·u_i) + ᵇR_p·c × m·g, each over its noise
(:class:`~cdpr_twin.calibrate.problem.Problem` states the model). Each cable is one term of
the sums, so its own parameters (exit and anchor point, its sensor's bias and gain) move only
that term: :func:`cable_jacobian` differentiates the terms alone, every parameter of a cable
in one vectorised evaluation, where differencing the whole balance would evaluate all m cables
twice per parameter (2 · 8 · 8 = 128 whole balances per Jacobian on ACROBOT).
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.calibrate.parameter_layout import Layout
from cdpr_twin.math.kinematics import pulley_vectors

TERMS = (("exit", 3), ("anchor", 3), ("tension_bias", 1), ("tension_gain", 1))
"""A cable's parameters that its balance term depends on, and how many of each."""


def wrench_residuals(problem, mod) -> np.ndarray:
    """The wrench balance residuals of ``problem`` for the model ``mod``.

    Args:
        problem: the :class:`~cdpr_twin.calibrate.problem.Problem` (its poses with every cable
            taut, readings, nominal geometry and noise).
        mod: the :class:`~cdpr_twin.calibrate.problem.Model` the parameters describe.

    Returns:
        (6 · n_force_poses,) force and moment per pose, unitless.
    """
    k, g, n = problem.force_k, problem.nominal, problem.noise
    if not len(k):  # no balance (force_std None), or no pose with every cable taut
        return np.zeros(0)
    T = mod.T_base_platform[k]
    rb = np.einsum("nij,cj->nci", T[:, :3, :3], mod.b_platform)  # ᵇR_p·b_i
    b = rb + T[:, None, :3, 3]
    a = np.broadcast_to(mod.a_base, b.shape).reshape(-1, 3)
    _, u = pulley_vectors(a, np.tile(g.pulley_radius, len(k)), b.reshape(-1, 3))
    tau = (problem.obs.tensions[k] - mod.tension_bias) / (1.0 + mod.tension_gain)
    f = tau[:, :, None] * u.reshape(len(k), -1, 3)  # what each cable's tension balances
    weight = g.mass * g.gravity
    F = f.sum(axis=1) - weight
    M = -np.cross(rb, f).sum(axis=1) + np.cross(T[:, :3, :3] @ g.com_platform, weight)
    return np.hstack([F / n.force_std, M / n.moment_std]).ravel()


def cable_columns(layout: Layout) -> list[int]:
    """The columns :func:`cable_jacobian` gives, cable by cable (those estimated)."""
    return [c for i in range(layout.m) for name, _ in TERMS for c in layout.columns(name, i)]


def cable_jacobian(problem, mod, h: float) -> np.ndarray:
    """Central differences of the balance over each cable's own parameters, term by term.

    Args:
        problem: as :func:`wrench_residuals`.
        mod: the model where to differentiate.
        h: step [m, N or unitless].

    Returns:
        (6 · n_force_poses, len(cable_columns)) the derivatives, columns as
        :func:`cable_columns` orders them.
    """
    L, k, n = problem.layout, problem.force_k, problem.noise
    T = mod.T_base_platform[k]
    scale = np.array([1 / n.force_std] * 3 + [1 / n.moment_std] * 3)
    out = []
    for i in range(L.m):
        # the cable's 8 parameters (exit, anchor, bias, gain), each of the p estimated moved
        # by +h then −h: (2p, 8)
        base = np.concatenate(
            [mod.a_base[i], mod.b_platform[i], [mod.tension_bias[i], mod.tension_gain[i]]]
        )
        moved = [
            at + j
            for at, (name, w) in zip((0, 3, 6, 7), TERMS, strict=True)
            if L.columns(name, i)
            for j in range(w)
        ]
        if not moved:
            continue
        P = np.tile(base, (2 * len(moved), 1))
        P[2 * np.arange(len(moved)), moved] += h
        P[2 * np.arange(len(moved)) + 1, moved] -= h
        rb = np.einsum("nij,qj->qni", T[:, :3, :3], P[:, 3:6])  # (2p, K, 3)
        b = (rb + T[None, :, :3, 3]).reshape(-1, 3)
        a = np.repeat(P[:, :3], len(k), axis=0)
        _, u = pulley_vectors(a, np.full(len(b), problem.nominal.pulley_radius[i]), b)
        tau = (problem.obs.tensions[k, i] - P[:, 6:7]) / (1.0 + P[:, 7:8])  # (2p, K)
        f = tau[:, :, None] * u.reshape(len(P), len(k), 3)
        w = np.concatenate([f, -np.cross(rb, f)], axis=2) * scale  # (2p, K, 6)
        d = (w[0::2] - w[1::2]) / (2.0 * h)  # (p, K, 6)
        out.append(d.reshape(len(moved), -1).T)
    return np.hstack(out) if out else np.zeros((6 * len(k), 0))
