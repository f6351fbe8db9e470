"""Cable kinematics of a CDPR (numpy only): lengths, pulley wrap, Jacobians, stretch.

Equation numbers refer to Zake et al., IROS 2021. Cable ``i`` runs from its exit point A_i to
its anchor point B_i. With pulleys (eq. 15-24) the cable descends the swivel axis z_i, touches
the sheave at A_i, wraps under it and leaves at the tangent point A'_i toward B_i.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from cdpr_twin.math.geometry import CdprGeometry

CableModel = Literal["straight", "pulley"]
TwistFrame = Literal["platform", "base"]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (k, 3) arrays (np.cross costs several times more at k = 8)."""
    return np.column_stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ]
    )


def anchor_points_base(geom: CdprGeometry, T_base_platform: np.ndarray) -> np.ndarray:
    """Anchor points B_i in F_b. Returns (m, 3) [m]."""
    return geom.b_platform @ T_base_platform[:3, :3].T + T_base_platform[:3, 3]


@dataclass(frozen=True, eq=False)
class PulleyState:
    """Pulley kinematics of every cable at one pose (eq. 15-24), all in F_b.

    Attributes:
        phi: (m,) swivel angle φ_i about z_i (eq. 20) [rad].
        center: (m, 3) sheave centre P_i = n_i (eq. 21) [m].
        tangent: (m, 3) exit tangent point A'_i [m].
        free_length: (m,) straight part L_i from A'_i to B_i (eq. 24) [m].
        wrap_length: (m,) wrapped part l_pi from A_i to A'_i (eq. 16) [m].
        u: (m, 3) unit vectors from A'_i to B_i.
    """

    phi: np.ndarray
    center: np.ndarray
    tangent: np.ndarray
    free_length: np.ndarray
    wrap_length: np.ndarray
    u: np.ndarray

    @property
    def length(self) -> np.ndarray:
        """Full cable length l_fi = L_i + l_pi from A_i to B_i (eq. 15). (m,) [m]."""
        return self.free_length + self.wrap_length


def _pulley(a: np.ndarray, r: np.ndarray, b: np.ndarray) -> PulleyState:
    """Eq. 15-24 on arrays: exit points a (k, 3), radii r (k,), anchor points b (k, 3) in F_b."""
    l_vec = b - a
    phi = np.arctan2(l_vec[:, 1], l_vec[:, 0])  # eq. 20
    x_i = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    n = a + r[:, None] * x_i  # eq. 21
    m = b - n  # eq. 23
    m_norm = np.sqrt(np.einsum("ij,ij->i", m, m))
    free = np.sqrt(np.maximum(m_norm**2 - r**2, 0.0))  # eq. 24
    beta = -np.arctan2(free, r)  # eq. 18
    gamma = np.arcsin(np.clip((a[:, 2] - b[:, 2]) / m_norm, -1.0, 1.0))  # eq. 19
    alpha = -beta + gamma  # eq. 17
    wrap = r * (np.pi - alpha)  # eq. 16
    # Tangent point: rotate the unit vector P→B "downward" in the pulley plane by ψ, cos ψ = r/|m|.
    e_h = np.einsum("ij,ij->i", m, x_i) / m_norm
    e_z = m[:, 2] / m_norm
    cos_psi = r / m_norm
    sin_psi = free / m_norm
    c_h = r * (cos_psi * e_h + sin_psi * e_z)
    c_z = r * (-sin_psi * e_h + cos_psi * e_z)
    tangent = n + c_h[:, None] * x_i
    tangent[:, 2] += c_z
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (b - tangent) / free[:, None]
    return PulleyState(phi=phi, center=n, tangent=tangent, free_length=free, wrap_length=wrap, u=u)


def pulley_lengths(a: np.ndarray, r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Full cable lengths l_f = L + l_p (eq. 15-24) of any stack of cables, vectorised.

    Args:
        a: (k, 3) exit points in F_b [m].
        r: (k,) sheave radii [m].
        b: (k, 3) anchor points in F_b [m].

    Returns:
        (k,) lengths from A_i around the sheave to B_i [m].
    """
    return pulley_vectors(a, r, b)[0]


def pulley_vectors(a: np.ndarray, r: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full cable lengths (eq. 15-24) and the free segments' directions, vectorised.

    Args:
        a: (k, 3) exit points in F_b [m].
        r: (k,) sheave radii [m].
        b: (k, 3) anchor points in F_b [m].

    Returns:
        ``(lengths, u)``: (k,) lengths from A_i around the sheave to B_i [m], and (k, 3) unit
        vectors from the exit tangent point A'_i toward B_i (a taut cable pulls its anchor
        along −u).
    """
    s = _pulley(a, r, b)
    return s.length, s.u


def pulley_state(geom: CdprGeometry, T_base_platform: np.ndarray) -> PulleyState:
    """Pulley kinematics (eq. 15-24) of every cable at a platform pose.

    Args:
        geom: CDPR geometry.
        T_base_platform: (4, 4) platform pose.

    Returns:
        The :class:`PulleyState`.
    """
    b = anchor_points_base(geom, T_base_platform)
    return _pulley(geom.a_base, geom.pulley_radius, b)


def lengths_and_jacobian(
    a_base: np.ndarray,
    b_platform: np.ndarray,
    pulley_radius: np.ndarray | None,
    T_base_platform: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Cable lengths and platform-frame Jacobian in one pass, for any subset of cables.

    The hot path of the model-based estimators: arrays in, no validation.

    Args:
        a_base: (k, 3) exit points in F_b [m].
        b_platform: (k, 3) anchor points in F_p [m].
        pulley_radius: (k,) sheave radii [m], or ``None`` for straight cables.
        T_base_platform: (4, 4) platform pose.

    Returns:
        ``(lengths, A)``: (k,) lengths [m] and (k, 6) Jacobian for ᵖv_p (eq. 6).
    """
    R = T_base_platform[:3, :3]
    b = b_platform @ R.T + T_base_platform[:3, 3]
    if pulley_radius is None:
        l_vec = b - a_base
        lengths = np.sqrt(np.einsum("ij,ij->i", l_vec, l_vec))
        u = l_vec / lengths[:, None]
    else:
        s = _pulley(a_base, pulley_radius, b)
        lengths, u = s.length, s.u
    u_p = u @ R
    return lengths, np.hstack([u_p, _cross(b_platform, u_p)])


def cable_vectors(
    geom: CdprGeometry, T_base_platform: np.ndarray, model: CableModel = "straight"
) -> tuple[np.ndarray, np.ndarray]:
    """Cable lengths and unit direction vectors in F_b.

    Args:
        geom: CDPR geometry.
        T_base_platform: (4, 4) platform pose.
        model: ``"straight"`` (A_i to B_i, eq. 7) or ``"pulley"`` (eq. 15-24; the direction is
            that of the free segment A'_i → B_i).

    Returns:
        ``(lengths, u_base)``: (m,) lengths [m] and (m, 3) unit vectors pointing toward B_i.
    """
    if model == "straight":
        l_vec = anchor_points_base(geom, T_base_platform) - geom.a_base
        lengths = np.linalg.norm(l_vec, axis=1)
        return lengths, l_vec / lengths[:, None]
    if model == "pulley":
        ps = pulley_state(geom, T_base_platform)
        return ps.length, ps.u
    raise ValueError(f"unknown cable model {model!r}; use 'straight' or 'pulley'")


def cable_lengths(
    geom: CdprGeometry, T_base_platform: np.ndarray, model: CableModel = "straight"
) -> np.ndarray:
    """Cable lengths from A_i to B_i (eq. 7 or eq. 15). Returns (m,) [m]."""
    return cable_vectors(geom, T_base_platform, model)[0]


def jacobian(
    geom: CdprGeometry,
    T_base_platform: np.ndarray,
    frame: TwistFrame = "platform",
    model: CableModel = "straight",
) -> np.ndarray:
    """Forward Jacobian A with l̇ = A · twist (eq. 5-6, eq. 30).

    Args:
        geom: CDPR geometry.
        T_base_platform: (4, 4) platform pose.
        frame: ``"platform"``: twist = ᵖv_p = [v, ω] of the platform origin expressed in F_p
            (eq. 6). ``"base"``: twist = ᵇv_p = [v, ω] of the platform origin expressed in F_b
            (eq. 30).
        model: cable model for the lengths being differentiated (``"straight"`` or
            ``"pulley"``; with pulleys the exact derivative uses the free segment's direction).

    Returns:
        (m, 6) Jacobian.
    """
    _, u = cable_vectors(geom, T_base_platform, model)
    R = T_base_platform[:3, :3]
    if frame == "platform":
        u_p = u @ R  # rows: Rᵀ u_i
        return np.hstack([u_p, _cross(geom.b_platform, u_p)])
    if frame == "base":
        rb = geom.b_platform @ R.T
        return np.hstack([u, _cross(rb, u)])
    raise ValueError(f"unknown twist frame {frame!r}; use 'platform' or 'base'")


def gravity_wrench(geom: CdprGeometry, T_base_platform: np.ndarray) -> np.ndarray:
    """Gravity wrench on the platform at its origin, in F_b: [f, moment]. Returns (6,) [N, N·m]."""
    f = geom.mass * geom.gravity
    c = T_base_platform[:3, :3] @ geom.com_platform
    return np.concatenate([f, np.cross(c, f)])


def stiffness_matrix(
    geom: CdprGeometry,
    T_base_platform: np.ndarray,
    rest_lengths: np.ndarray,
    model: CableModel = "pulley",
) -> np.ndarray:
    """Elastic Cartesian stiffness K = Aᵀ diag(E·S / l0) A of the platform, in F_b.

    The geometric (tension) term, of order τ/L ≈ 30 N/m against E·S/l ≈ 3.5e5 N/m on ACROBOT,
    is left out: it changes K by about 1e-4.

    Args:
        geom: CDPR geometry.
        T_base_platform: (4, 4) platform pose.
        rest_lengths: (m,) unstretched lengths l0 of the taut cables [m].
        model: cable model.

    Returns:
        (6, 6) stiffness for displacements [δp, δθ] in F_b: a wrench δw applied at the platform
        origin moves it by K⁻¹ δw.
    """
    A = jacobian(geom, T_base_platform, "base", model)
    return A.T @ (A * (geom.es / np.asarray(rest_lengths))[:, None])


def elastic_elongation(
    lengths: np.ndarray,
    tensions: np.ndarray,
    es: np.ndarray,
    tensions0: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Cable elongation δl_i = (τ_i − τ_i(0)) l_i / (E·S) (eq. 14).

    A hot path of the elastic estimators: pass numpy arrays, no conversion is made.

    Args:
        lengths: (m,) cable lengths l_i [m] (the encoders' unstretched lengths).
        tensions: (m,) measured tensions τ_i [N].
        es: (m,) axial stiffness E·S [N].
        tensions0: τ_i(0), tensions at which the lengths were zeroed [N].

    Returns:
        (m,) elongations [m].
    """
    return (tensions - tensions0) * lengths / es


def rest_lengths(lengths: np.ndarray, tensions: np.ndarray, es: np.ndarray) -> np.ndarray:
    """Unstretched lengths l0 that stretch to ``lengths`` under ``tensions``.

    The inverse of the elastic law τ = E·S/l0 · (L − l0): l0 = E·S·L / (E·S + τ).

    Args:
        lengths: (m,) stretched lengths L [m].
        tensions: (m,) tensions τ ≥ 0 [N].
        es: (m,) axial stiffness E·S [N].

    Returns:
        (m,) rest lengths [m].
    """
    return es * lengths / (es + tensions)


def start_error_transfer(
    geom: CdprGeometry,
    T_start: np.ndarray,
    T_end: np.ndarray,
    model: CableModel = "pulley",
) -> np.ndarray:
    """First-order map of a start-pose error to the pose error after an open-loop move.

    The winches pay out the planned length changes l(T_end) − l(T_start) from wherever the
    platform truly started: a start error δ₀ leaves every cable A(T_start) δ₀ longer than planned
    at the end, and the platform settles where the lengths fit best (rigid cables, all taut):
    δ_end = A(T_end)⁺ A(T_start) δ₀. It is why a robot homed to within its repeatability misses
    an open-loop waypoint by about as much, however well its geometry is known.

    Args:
        geom: CDPR geometry.
        T_start: (4, 4) the planned start pose.
        T_end: (4, 4) the planned end pose.
        model: cable model of the lengths.

    Returns:
        (6, 6) the map of base-frame pose errors [δp (m), δθ (rad)].
    """
    A_end = jacobian(geom, T_end, "base", model)
    return np.linalg.pinv(A_end) @ jacobian(geom, T_start, "base", model)
