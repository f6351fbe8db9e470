"""A discretised stretchable cable in MuJoCo: point masses joined by elastic tendons.

The reference for :mod:`cdpr_twin.math.catenary` (MuJoCo's ``cable`` composite is inextensible, and
its tendons are massless). A cable of unstretched length L0, stiffness E·S and linear density ρ
between two fixed points becomes N segments: N − 1 free nodes of mass ρ L0 / N (three slide
joints each), joined by spatial tendons of stiffness N E·S / L0 and rest length L0 / N; the two
half-segment masses at the ends rest on the supports. :func:`chain_end_forces` finds the static
equilibrium with MuJoCo's own forces (Newton on ``qfrc_passive − qfrc_bias``, MuJoCo's spring
and gravity forces, with finite-difference Jacobians) and returns the forces on the two ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from cdpr_twin.sim.model import SimulationError

G = 9.81


@dataclass(frozen=True, eq=False)
class ChainResult:
    """The discretised cable at rest.

    Attributes:
        force_low: (3,) force of the cable on the lower point [N].
        force_high: (3,) force of the cable on the upper point [N].
        nodes: (N + 1, 3) node positions, ends included [m].
        residual: largest generalised force left on a node [N].
    """

    force_low: np.ndarray
    force_high: np.ndarray
    nodes: np.ndarray
    residual: float


def chain_model(l0: float, es: float, rho: float, low, high, n: int) -> mujoco.MjModel:
    """The N-segment chain as a compiled model (nodes start on the chord)."""
    spec = mujoco.MjSpec()
    spec.option.gravity = [0.0, 0.0, -G]
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    spec.worldbody.add_site(name="n0", pos=low)
    spec.worldbody.add_site(name=f"n{n}", pos=high)
    for k in range(1, n):
        body = spec.worldbody.add_body(name=f"node{k}", pos=low + (high - low) * k / n)
        for axis in np.eye(3):
            body.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[0.01, 0, 0],
            mass=rho * l0 / n,
            contype=0,
            conaffinity=0,
        )
        body.add_site(name=f"n{k}")
    for k in range(n):
        t = spec.add_tendon(name=f"seg{k}", stiffness=es * n / l0, springlength=[l0 / n, l0 / n])
        t.wrap_site(f"n{k}")
        t.wrap_site(f"n{k + 1}")
    return spec.compile()


def _residual(model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray) -> np.ndarray:
    data.qpos[:] = q
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    return data.qfrc_passive - data.qfrc_bias  # springs + gravity at rest


def _solve(model: mujoco.MjModel, data: mujoco.MjData, tol: float) -> float:
    """Newton with finite-difference Jacobians and a backtracking line search."""
    q = data.qpos.copy()
    r = _residual(model, data, q)
    for _ in range(100):
        if np.max(np.abs(r)) < tol:
            break
        J = np.empty((model.nv, model.nv))
        for j in range(model.nv):
            dq = np.zeros(model.nv)
            dq[j] = 1e-7
            J[:, j] = (_residual(model, data, q + dq) - _residual(model, data, q - dq)) / 2e-7
        step = np.linalg.solve(J, -r)
        scale = 1.0
        while scale > 1e-6:
            r_new = _residual(model, data, q + scale * step)
            if np.linalg.norm(r_new) < np.linalg.norm(r):
                break
            scale *= 0.5
        q, r = q + scale * step, r_new
    _residual(model, data, q)
    return float(np.max(np.abs(r)))


def chain_end_forces(
    l0: float, es: float, rho: float, low, high, n: int, tol: float | None = None
) -> ChainResult:
    """Forces of an N-segment MuJoCo cable on its fixed ends, at static equilibrium.

    Args:
        l0: unstretched length [m].
        es: axial stiffness E·S [N].
        rho: mass per unstretched metre [kg/m].
        low: (3,) lower end [m].
        high: (3,) upper end [m].
        n: number of segments (≥ 2).
        tol: largest generalised force left on a node [N] (default: the round-off floor of
            the springs, 1e-12 · N E·S / L0 · the span).

    Returns:
        The :class:`ChainResult`.

    Raises:
        SimulationError: when Newton does not reach ``tol``.
    """
    model = chain_model(l0, es, rho, low, high, n)
    span = float(np.linalg.norm(np.subtract(high, low)))
    tol = 1e-12 * es * n / l0 * span if tol is None else tol
    data = mujoco.MjData(model)
    residual = _solve(model, data, tol)
    if residual > tol:
        raise SimulationError(f"the {n}-segment cable found no equilibrium ({residual:.3g} N)")
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"n{k}") for k in range(n + 1)]
    nodes = data.site_xpos[ids].copy()
    k, rest = es * n / l0, l0 / n
    end_weight = np.array([0.0, 0.0, -0.5 * rho * l0 / n * G])  # half a segment on each end

    def pull(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # the segment a → b pulls a toward b
        d = b - a
        length = np.linalg.norm(d)
        return k * (length - rest) * d / length

    return ChainResult(
        force_low=pull(nodes[0], nodes[1]) + end_weight,
        force_high=pull(nodes[-1], nodes[-2]) + end_weight,
        nodes=nodes,
        residual=residual,
    )
