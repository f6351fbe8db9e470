"""Fast paths of the fused filter's per-update arithmetic, bit-identical to the reference.

An update of :mod:`cdpr_twin.estimators.fused` works on arrays of 3 to 88 elements, where
NumPy's per-call overhead (about a microsecond) outweighs the arithmetic. The functions here
compute what :mod:`cdpr_twin.estimators.fused_models` and :mod:`cdpr_twin.se3` compute,
operation for operation, with fewer calls:

- every elementwise step NumPy did on a few elements is done on Python floats, in the same
  order (IEEE-754 doubles either way: the same roundings);
- every matrix product, reduction and LAPACK call stays the same NumPy call on operands of the
  same shape and layout: BLAS fuses multiply-adds and chooses its own summation order, so a
  Python loop would round differently;
- what does not change between updates (the tag's corners, ``[p]×``) is built once.

Tests hold each function to its reference bit for bit (``tests/test_fused_fast.py``).
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.estimators.fused_models import Layout


def finite(values: np.ndarray) -> bool:
    """``np.all(np.isfinite(values))`` of a 1-D float array."""
    return all(map(math.isfinite, values.tolist()))


def taut(tensions: np.ndarray, clipped: np.ndarray | None, threshold: float) -> list[bool]:
    """The taut cables, ``(tensions > threshold) & ~clipped``, as m bools.

    Args:
        tensions: (m,) measured tensions [N].
        clipped: (m,) which readings sit at a limit of the sensor (bools), or ``None``.
        threshold: the taut threshold [N].
    """
    if clipped is None:
        return [t > threshold for t in tensions.tolist()]
    if clipped.dtype != bool:  # ~ is then a bitwise not, as it was
        return ((np.asarray(tensions) > threshold) & ~np.asarray(clipped)).tolist()
    return [
        t > threshold and not c for t, c in zip(tensions.tolist(), clipped.tolist(), strict=True)
    ]


def gate_cables(
    r: list[float], s: list[float], var: list[float], gate: float, taut: list[bool]
) -> tuple[bool, list[int]]:
    """Mahalanobis gate of each cable's innovation: r² > gate · (HPHᵀ + var).

    Args:
        r: m innovations [m].
        s: the m diagonal entries of H P Hᵀ [m²].
        var: m reading variances [m²].
        gate: the χ²(1) gate.
        taut: m bools, the taut cables.

    Returns:
        Whether a taut cable failed the gate, and the indices of the taut cables that passed.
    """
    gated = [ri * ri > gate * (si + vi) for ri, si, vi in zip(r, s, var, strict=True)]
    outlier = any(g and t for g, t in zip(gated, taut, strict=True))
    return outlier, [i for i, (t, g) in enumerate(zip(taut, gated, strict=True)) if t and not g]


def corrected_readings(
    lengths: list[float],
    tensions: list[float],
    rates: list[float],
    es: list[float],
    damping_time: float,
) -> list[float]:
    """``fused_models.corrected_readings`` on m floats each, bit for bit: m corrected [m]."""
    eta = damping_time
    return [
        x + x * t / e - eta * r for x, t, e, r in zip(lengths, tensions, es, rates, strict=True)
    ]


def cable_innovations(
    corrected: list[float],
    corrected_0: list[float],
    moved: list[float],
    lengths: list[float],
    lengths_0: list[float],
    rho: list[float],
    quantum: float,
) -> list[float]:
    """The cable readings' innovations y − h of the fused filter, as it computed them with NumPy.

    y = c − c₀ + q/2 (on a cable whose count moved: the quantisation's mean), h = L(T) − L(T₀)
    − ρ Δl, on m floats each.

    Args:
        corrected: the corrected readings c [m].
        corrected_0: those of the reference reading c₀ [m].
        moved: the encoder counts since the reference Δl [m].
        lengths: the model lengths L(T) [m].
        lengths_0: the model lengths L(T₀) [m].
        rho: the drum scale errors ρ.
        quantum: the encoder count q [m].

    Returns:
        m innovations [m].
    """
    half_q = 0.5 * quantum
    return [
        (c - c0 + (half_q if d != 0.0 else 0.0)) - ((ln - l0) - r * d)
        for c, c0, d, ln, l0, r in zip(
            corrected, corrected_0, moved, lengths, lengths_0, rho, strict=True
        )
    ]


def cable_noise_var(
    lengths: list[float],
    tensions: list[float],
    es: list[float],
    quantum: float,
    floor_std: float,
    tension_std: float,
    threshold: float,
) -> list[float]:
    """``fused_models.cable_noise_var`` of the tensions floored at 1e-9 N, bit for bit.

    As the filter calls it: ``cable_noise_var(lengths, np.maximum(tensions, 1e-9), …)``, on
    m floats each. The ×(3·threshold/τ)⁴ of a cable near slack goes through NumPy's power, as
    there; when no cable is near slack every factor is 1 and 1⁴ = 1 exactly.

    Returns:
        m variances [m²].
    """
    base = quantum**2 / 12.0 + floor_std**2
    th3 = 3.0 * threshold
    var, near = [], []
    for length, t, e in zip(lengths, tensions, es, strict=True):
        x = length * tension_std / e
        var.append(base + 2.0 * (x * x))
        near.append(max(th3 / max(max(t, 1e-9), 1e-9), 1.0))
    if any(v != 1.0 for v in near):
        return [v * p for v, p in zip(var, (np.array(near) ** 4).tolist(), strict=True)]
    return var


def joseph_update_in_place(
    P: np.ndarray, H: np.ndarray, R: np.ndarray, innovation: np.ndarray, corrected: int
) -> np.ndarray:
    """``fused_models.joseph_update`` writing P⁺ into P: only the leading rows and columns.

    Bit for bit the reference's (dx, P⁺) when P is symmetric outside its leading c × c block,
    as the fused filter keeps it (its prediction and the tag's anchoring write a row block and
    its transpose; only their diagonal blocks may be asymmetric by round-off). Then the update
    leaves ``P[c:, c:]`` as it is, and the reference's symmetrisation ½(P⁺ + P⁺ᵀ) changes only
    the leading c × c block: elsewhere it averages an entry with an equal one, exactly. The
    normalised innovation squared is not computed.

    Args:
        P: (n, n) prior covariance, overwritten with the posterior.
        H: (k, n) measurement Jacobian.
        R: (k, k) measurement noise covariance.
        innovation: (k,) measured − predicted.
        corrected: the number c of leading states corrected; the others are considered.

    Returns:
        (c,) the corrected states' part of dx (the considered states' is zero).
    """
    c = corrected
    PHt = P @ H.T
    S = H @ PHt + R
    S_inv = np.linalg.inv(S)
    K = PHt[:c] @ S_inv  # (c, k): the considered states' gain is zero
    KHP = K @ PHt.T  # (c, n)
    top = P[:c] - KHP  # P⁺'s leading rows, (c, n)
    top[:, :c] -= KHP[:, :c].T
    top[:, :c] += K @ S @ K.T
    lead = top[:, :c]
    top[:, :c] = 0.5 * (lead + lead.T)
    P[:c] = top
    P[c:, :c] = top[:, c:].T
    return K @ innovation


class CableColumns:
    """The fused filter's cable Jacobians with few NumPy calls, bit for bit.

    Args:
        layout: the state layout.
        m: the number of cables.
    """

    def __init__(self, layout: Layout, m: int) -> None:
        first = np.arange(m)[:, None] * layout.n  # each row's first flat index
        cols = 3 * np.arange(m)[:, None] + np.arange(3)  # (m, 3): cable i's three columns
        self.shape = (m, layout.n)
        self.geometry = layout.exit.stop > layout.exit.start
        self.exit = (first + layout.exit.start + cols).ravel()
        self.anchor = (first + layout.anchor.start + cols).ravel()
        self.drum = first[:, 0] + layout.drum.start + np.arange(m)

    def transition(
        self, rows: np.ndarray, R: np.ndarray, rows_prev: np.ndarray, R_prev: np.ndarray
    ) -> np.ndarray:
        """``geometry_rows(rows, R) − geometry_rows(rows_prev, R_prev)`` (m, n), bit for bit.

        Args:
            rows: (m, 6) Jacobian rows [u_p, b × u_p] at the new pose.
            R: (3, 3) its rotation.
            rows_prev: (m, 6) Jacobian rows at the previous pose.
            R_prev: (3, 3) its rotation.
        """
        u, u_prev = rows[:, :3], rows_prev[:, :3]
        G = np.zeros(self.shape)
        flat = G.reshape(-1)
        flat[self.exit] = (u_prev @ R_prev.T - u @ R.T).ravel()  # (−a) − (−b) is b − a
        flat[self.anchor] = (u - u_prev).ravel()
        return G

    def measurement(
        self,
        rows_now: np.ndarray,
        R_now: np.ndarray,
        rows_0: np.ndarray,
        R_0: np.ndarray,
        moved: list[float],
    ) -> np.ndarray:
        """The cable readings' H (m, n), bit for bit as the reference builds it.

        The reference: H = 0; H[:, POSE] = rows_now; H[:, START] = −rows_0;
        H[:, DRUM] = −diag(moved); H += G(rows_now, R_now); H −= G(rows_0, R_0), G from
        ``fused_models.geometry_rows`` (zero without the geometry states). Every entry is
        (h + g_now) − g_0 with h or both g zero: the added zeros turn a −0 into +0, and
        (0 + (−a)) − (−b) is (0 − a) + b.

        Args:
            rows_now: (m, 6) Jacobian rows at T.
            R_now: (3, 3) T's rotation.
            rows_0: (m, 6) Jacobian rows at T₀.
            R_0: (3, 3) T₀'s rotation.
            moved: m encoder counts since the reference reading [m].
        """
        H = np.zeros(self.shape)
        H[:, :6] = rows_now + 0.0
        H[:, 6:12] = 0.0 - rows_0
        flat = H.reshape(-1)
        flat[self.drum] = [0.0 - d for d in moved]
        if self.geometry:
            u_now, u_0 = rows_now[:, :3], rows_0[:, :3]
            flat[self.exit] = ((0.0 - u_now @ R_now.T) + u_0 @ R_0.T).ravel()
            flat[self.anchor] = ((0.0 + u_now) - u_0).ravel()
        return H


def adjoint(T: np.ndarray, out: np.ndarray | None = None, invert: bool = False) -> np.ndarray:
    """``se3.adjoint(T)``, or ``se3.adjoint(se3.inverse(T))``, bit for bit: (6, 6).

    Args:
        T: (4, 4) rigid transform.
        out: an array whose first 6 columns of its 6 rows are zeros, to write it into.
        invert: the adjoint of T's inverse.
    """
    if invert:
        R = T[:3, :3].T.copy()
        x, y, z = (-T[:3, :3].T @ T[:3, 3]).tolist()
    else:
        R = T[:3, :3]
        x, y, z = T[:3, 3].tolist()
    Ad = np.zeros((6, 6)) if out is None else out
    Ad[:3, :3] = R
    Ad[:3, 3:6] = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]) @ R
    Ad[3:6, 3:6] = R
    return Ad
