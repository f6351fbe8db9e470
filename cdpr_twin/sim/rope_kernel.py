"""The ropes' per-step update, compiled: the sheave's stick-slip, the dashpots, MuJoCo's forces.

:class:`cdpr_twin.sim.rope.RopePhysics` calls :func:`update_ropes` before every physics step
of ropes with internal state (creep or sheave friction). It is the arithmetic of the rope
model (:mod:`cdpr_twin.sim.rope`, the equations there) cable by cable, in the order NumPy
evaluated it elementwise before it was compiled, so that the results are the same to the bit;
one call in place of ~40 NumPy calls makes a step 3–4× cheaper.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

jit = njit(cache=True, nogil=True)
"""Compile, cache on disk, release the GIL."""

# rows of the state array (m columns, one per cable)
U_P, U_RATE, EPS_D_P, EPS_D_W, ON, GROOVE = range(6)
# rows of the constants array
ES0, ES_M = range(2)
# entries of the parameters array
ENTRY, DRUM, EFFICIENCY, DAMPING, TIMESTEP, DECAY, VISCOELASTIC = range(7)


@jit
def face(e, lw, a, b, length, total, pp, pw):
    """u_p and ∂u_p/∂L on a face a·τ_w = b·τ_p of the friction cone (``RopePhysics._slide``).

    The root of C u² − (A + B + C T) u + B T = 0 near B T/(A + B), in the form that stays
    exact as C → 0. All arguments are floats of one cable; returns two floats.
    """
    big_b = b * e * length
    bt = big_b * total
    c = b * (e + pp) - a * (e + pw)
    half = a * e * lw + big_b + c * total
    root = 2.0 * bt / (half + math.sqrt(half * half - 4.0 * c * bt))
    uw2 = total - root
    uw2 *= uw2
    return root, b * root * uw2 / (a * lw * root * root + b * length * uw2)


@jit
def update_ropes(
    ten_length: np.ndarray,
    act: np.ndarray,
    tendons: np.ndarray,
    actuators: np.ndarray,
    state: np.ndarray,
    consts: np.ndarray,
    params: np.ndarray,
    gain: np.ndarray,
    bias: np.ndarray,
    relax: bool,
) -> None:
    """Slide the cables over the sheaves, relax the dashpots, set MuJoCo's forces, in place.

    Args:
        ten_length: MuJoCo's tendon lengths (``data.ten_length``) [m].
        act: MuJoCo's activations (``data.act``): the winches' paid-out l0 [m].
        tendons: (m,) the cables' tendon ids.
        actuators: (m,) the winches' actuator ids (their activations' too).
        state: (6, m) u_p [m], u̇_p [m/s], the platform and drum segments' dashpot strains,
            1 for an intact cable (0: cut), the groove's stretch of a lagging swivel [m];
            u_p, u̇_p and the strains are updated.
        consts: (2, m) E₀ and E_m [N].
        params: (7,) the entry segment [m], the drum segment l_d [m], the sheave's efficiency
            η, the damping time [s], the physics step h [s], exp(−h/t_σ), 1 for creep (0: none).
        gain: (m, 10) the winches' ``actuator_gainprm`` rows (set to 0 in column 0).
        bias: (m, 10) the winches' ``actuator_biasprm`` rows (columns 0–2 set).
        relax: advance the dashpots by one step and take u̇_p from this update.
    """
    entry, lw, eta = params[ENTRY], params[DRUM], params[EFFICIENCY]
    damping, h, decay = params[DAMPING], params[TIMESTEP], params[DECAY]
    viscoelastic = params[VISCOELASTIC] != 0.0
    for i in range(state.shape[1]):
        e, on = consts[ES0, i], state[ON, i]
        tendon = ten_length[tendons[i]]
        length = tendon - entry + state[GROOVE, i]
        l0 = act[actuators[i]]
        # the Maxwell arms' E_m·ε_d (zero for elastic ropes)
        pp = consts[ES_M, i] * state[EPS_D_P, i] if viscoelastic else 0.0
        pw = consts[ES_M, i] * state[EPS_D_W, i] if viscoelastic else 0.0
        follow = 0.0
        if lw > 0.0:
            total = l0 + lw
            u = state[U_P, i]
            if eta == 1.0:  # no friction: equal tensions, the cable slides
                u, follow = face(e, lw, 1.0, 1.0, length, total, pp, pw)
            else:
                # a slack side pulls nothing
                tau_p = max(e * (length / u - 1.0) - pp, 0.0)
                tau_w = max(e * (lw / (total - u) - 1.0) - pw, 0.0)
                # the face of the friction cone: the platform side pulls the cable over the
                # sheave (paying out), the winch side does (reeling in), or neither (stuck)
                if tau_w < eta * tau_p:
                    u, follow = face(e, lw, 1.0, eta, length, total, pp, pw)
                elif tau_p < eta * tau_w:
                    u, follow = face(e, lw, eta, 1.0, length, total, pp, pw)
            eps_w = lw / (total - u) - 1.0
        else:
            u = l0
            eps_w = 0.0
        if relax:  # the rate cable slides over the sheave (and out of the drum)
            state[U_RATE, i] = (u - state[U_P, i]) / h
        state[U_P, i] = u
        k = e * on / u
        stretch = length / u
        tau = (k * length - e - pp) * on  # the platform segment's, at L
        # MuJoCo steps from the next length L': τ(L') = τ + k_eff·(L' − L), where a sliding
        # cable gives way, k_eff = k·(1 − (L/u)·∂u/∂L) (the segments in series)
        stiff = k * (1.0 - stretch * follow)
        gain[i, 0] = 0.0
        # the damping acts on the strain rate, ∝ L̇ − (L/u)·u̇
        bias[i, 0] = stiff * tendon - tau + k * damping * stretch * state[U_RATE, i]
        bias[i, 1] = -stiff
        bias[i, 2] = k * -damping
        if relax and viscoelastic:
            eps_p = length / u - 1.0
            if lw <= 0.0:
                eps_w = eps_p
            # exact for the strain held over the step: ε_d ← ε + (ε_d − ε)·exp(−h/t_σ)
            state[EPS_D_P, i] = (state[EPS_D_P, i] - eps_p) * decay + eps_p
            state[EPS_D_W, i] = (state[EPS_D_W, i] - eps_w) * decay + eps_w
