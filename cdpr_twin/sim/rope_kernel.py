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


# ------------------------------------------------------------------------------ the swivels
@jit
def groove_exit(x, z, cx, cz, r):
    """Where the cable leaves the sheave toward a point (x, z) of the sheave's plane.

    The cable runs counter-clockwise in the (x, z) plane of the swivel's frame (down the
    swivel axis, under the sheave, out): it leaves at the tangent point
    T = c + r(cos θ, sin θ) with θ = β − γ, β the direction of (x, z) from the sheave's
    centre c and cos γ = r/|(x, z) − c|.

    Args:
        x: the point's distance from the swivel axis in the sheave's plane [m].
        z: the point's height along the swivel axis [m].
        cx: the sheave centre's distance from the axis [m].
        cz: the sheave centre's height along the axis [m].
        r: the wrap radius [m].

    Returns:
        The exit angle θ [rad], T's distance from the axis x_t and height z_t [m], and the
        free span |(x, z) − T| [m].
    """
    dx, dz = x - cx, z - cz
    dist2 = dx * dx + dz * dz
    theta = math.atan2(dz, dx) - math.acos(r / math.sqrt(dist2))
    return theta, cx + r * math.cos(theta), cz + r * math.sin(theta), math.sqrt(dist2 - r * r)


@jit
def swivel_equilibrium(alpha, rho, z, cx, cz, r, friction_arm):
    """The swivel's restoring moment and bearing friction per newton of cable tension.

    The swivel lags its cable by α: B_i sits at (ρ cos α, ρ sin α, z) in the swivel's frame
    (x in the sheave's plane, z up its axis). The cable stays in the groove and leaves it
    where its projection on the plane is tangent (:func:`groove_exit`), then runs straight to
    B_i at a fleet angle. Its pull at T, τ·û, turns the swivel toward B_i by
    τ·x_t·ρ sin α/ℓ (ℓ the free span); the cable loads the bearing with P = τ·|û + ẑ| (it
    arrives down the axis, −ẑ, and leaves along û).

    Args:
        alpha: the lag α = ψ − φ [rad].
        rho: B_i's distance from the swivel axis [m].
        z: B_i's height along the swivel axis [m].
        cx: the sheave centre's distance from the axis [m].
        cz: the sheave centre's height along the axis [m].
        r: the wrap radius [m].
        friction_arm: μ·d/2, the bearing's friction moment per newton of load [m].

    Returns:
        The restoring moment x_t·ρ·sin α/ℓ and the friction moment μ(d/2)·|û + ẑ|, both
        per newton of tension [m].
    """
    y = rho * math.sin(alpha)
    x = rho * math.cos(alpha)
    _, x_t, z_t, span = groove_exit(x, z, cx, cz, r)
    span3 = math.sqrt(span * span + y * y)
    ux, uy, uz = (x - x_t) / span3, y / span3, (z - z_t) / span3
    return x_t * y / span3, friction_arm * math.sqrt(ux * ux + uy * uy + (uz + 1.0) ** 2)


@jit
def groove_stretch(alpha, rho, z, cx, cz, r):
    """How much longer the cable in its groove is on a swivel lagging by α than on one aligned.

    ΔL = r·(θ(α) − θ(0)) + √(ℓ(α)² + (ρ sin α)²) − ℓ(0) (arc and free span, see
    :func:`swivel_equilibrium` for the arguments), ≈ x_t·ρ·α²/(2ℓ) ≥ 0 [m].
    """
    theta0, _, _, span0 = groove_exit(rho, z, cx, cz, r)
    theta, _, _, span = groove_exit(rho * math.cos(alpha), z, cx, cz, r)
    y = rho * math.sin(alpha)
    return r * (theta - theta0) + (math.sqrt(span * span + y * y) - span0)


@jit
def swivel_slip(alpha, rho, z, cx, cz, r, friction_arm):
    """The lag after Coulomb's law for a massless swivel: held, or turned to the friction cone.

    A swivel whose cable's moment exceeds its bearing's friction turns toward B_i until they
    balance, sin α* = μ(d/2)·|û + ẑ|·ℓ/(x_t·ρ) (:func:`swivel_equilibrium`, which gives the
    arguments; both moments scale with τ, so α* does not depend on it). α* is found by
    fixed-point iteration: its terms move with cos α only, so each gains a factor O(α*²).
    A swivel whose cable leaves the sheave across its axis (x_t ≤ 0: a sheave offset inward
    by more than r(1 − cos θ)) has no aligning moment: it is held.

    Returns:
        The lag α after the swivel has turned (α itself when held) [rad].
    """
    moment, friction = swivel_equilibrium(alpha, rho, z, cx, cz, r, friction_arm)
    if moment * math.copysign(1.0, alpha) <= friction:
        return alpha
    a = alpha
    for _ in range(3):
        moment, friction = swivel_equilibrium(a, rho, z, cx, cz, r, friction_arm)
        a = math.copysign(math.asin(abs(friction * math.sin(a) / moment)), a)
    return a


@jit
def turn_swivels(psi, rho, z, yaw, taut, centre, r, friction_arm, lag, state):
    """Let the swivels follow their cables' azimuths by Coulomb's law, in place.

    Args:
        psi: (m,) B_i's azimuths in the swivels' tilted frames [rad].
        rho: (m,) B_i's distances from the swivel axes [m].
        z: (m,) B_i's heights along the swivel axes [m].
        yaw: (m,) the swivels' yaws φ [rad], updated (a held swivel's exactly kept).
        taut: (m,) which cables pull (a slack cable's swivel is held).
        centre: (m, 2) the sheave centres (x, z) in the swivels' frames [m].
        r: (m,) the wrap radii [m].
        friction_arm: μ·d/2 [m].
        lag: (m,) the lags α = ψ − φ [rad], set.
        state: (6, m) the ropes' state: the groove's stretch row is set [m].
    """
    for i in range(psi.shape[0]):
        alpha = (psi[i] - yaw[i] + math.pi) % (2.0 * math.pi) - math.pi
        if taut[i]:
            turned = swivel_slip(
                alpha, rho[i], z[i], centre[i, 0], centre[i, 1], r[i], friction_arm
            )
            if turned != alpha:
                yaw[i] = psi[i] - turned
                alpha = turned
        lag[i] = alpha
        state[GROOVE, i] = groove_stretch(alpha, rho[i], z[i], centre[i, 0], centre[i, 1], r[i])
