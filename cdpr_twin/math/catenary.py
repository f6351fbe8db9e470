"""Irvine's elastic catenary: a heavy, stretchable cable hanging between two points (numpy).

A cable of unstretched length L0, axial stiffness E·S and weight w per unstretched metre spans
from a lower point to an upper one, h apart horizontally and v vertically (v may be negative).
With H the (constant) horizontal tension and V0 the vertical tension component at the lower
end, at unstretched arc length s from the lower end V(s) = V0 + w s, and (Irvine, *Cable
Structures*, MIT Press 1981, §2.2)

    x(s) = H s / ES + (H / w) [asinh(V(s)/H) − asinh(V0/H)]
    z(s) = (V0 s + w s²/2) / ES + (1 / w) [√(H² + V(s)²) − √(H² + V0²)].

:func:`solve_catenary` finds (H, V0) with x(L0) = h and z(L0) = v by Newton's method on the
analytic Jacobian. The cable pulls the lower point with (H ê, V0) (ê the horizontal unit vector
toward the upper point) and the upper one with (−H ê, −(V0 + w L0)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class CatenaryError(ValueError):
    """The cable is slack (no taut catenary spans the points) or Newton did not converge."""


@dataclass(frozen=True)
class Catenary:
    """A solved hanging cable.

    Attributes:
        horizontal: H, the horizontal tension [N].
        vertical_low: V0, vertical tension component at the lower end [N] (up is positive).
        l0: unstretched length [m]; es: E·S [N]; w: weight per unstretched metre [N/m].
        span_h, span_v: horizontal and vertical span from the lower end [m].
        iterations: Newton iterations used.
    """

    horizontal: float
    vertical_low: float
    l0: float
    es: float
    w: float
    span_h: float
    span_v: float
    iterations: int

    @property
    def vertical_high(self) -> float:
        """V0 + w L0, the vertical tension component at the upper end [N]."""
        return self.vertical_low + self.w * self.l0

    @property
    def tension_low(self) -> float:
        """Tension at the lower end [N]."""
        return math.hypot(self.horizontal, self.vertical_low)

    @property
    def tension_high(self) -> float:
        """Tension at the upper end [N]."""
        return math.hypot(self.horizontal, self.vertical_high)

    @property
    def length(self) -> float:
        """The stretched arc length L0 + ∫ T/ES ds [m]."""
        H, V0, w = self.horizontal, self.vertical_low, self.w

        def integral(V: float) -> float:  # ∫ T dV / w, T = √(H² + V²)
            return (V * math.hypot(H, V) + H * H * math.asinh(V / H)) / (2.0 * w)

        return self.l0 + (integral(self.vertical_high) - integral(V0)) / self.es

    @property
    def sag(self) -> float:
        """Largest vertical distance of the cable below its chord [m] (sampled, 2001 points)."""
        s = np.linspace(0.0, self.l0, 2001)
        x, z = _shape(self.horizontal, self.vertical_low, s, self.es, self.w)
        return float(np.max(self.span_v * x / self.span_h - z))


def hangs_vertically(gravity) -> bool:
    """Whether ``gravity`` (3,) [m/s²] points down z (or is zero): a catenary hangs vertically."""
    return gravity[0] == 0 and gravity[1] == 0 and gravity[2] <= 0


def _plus_minus(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(√(1+x²) + x, √(1+x²) − x), each without cancellation."""
    r = np.hypot(1.0, x)
    big = np.where(x >= 0, r + x, r - x)  # the sum of two positives
    return np.where(x >= 0, big, 1.0 / big), np.where(x >= 0, 1.0 / big, big)


def _g(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """[x√(1+y²) − y√(1+x²)] / (x − y), stable as x → y (sinh of asinh x − asinh y)."""
    ap, am = _plus_minus(x)
    bp, bm = _plus_minus(y)
    a, b = np.hypot(1.0, x), np.hypot(1.0, y)
    return (am + bm) * (ap + bp) / (2.0 * (a + b))


def _terms(H: float, V0: float, s, w: float) -> tuple[np.ndarray, ...]:
    """Four differences at arc length s, each free of the 1/w cancellation (exact as w → 0).

    With V = V0 + w s and T = √(H² + V²): [asinh(V/H) − asinh(V0/H)]/w, (T − T0)/w,
    H (1/T − 1/T0)/w and (V/T − V0/T0)/w.
    """
    s = np.asarray(s, dtype=float)
    V = V0 + w * s
    T, T0 = np.hypot(H, V), math.hypot(H, V0)
    g = _g(V / H, np.full_like(V, V0 / H))
    D = w * s / H * g  # sinh(asinh(V/H) − asinh(V0/H))
    small = np.abs(D) < 1e-6
    asinhc = np.where(small, 1.0 - D * D / 6.0, np.arcsinh(D) / np.where(small, 1.0, D))
    dasinh_w = s * g / H * asinhc
    dT_w = s * (V + V0) / (T + T0)
    dinv = -H * s * (V + V0) / (T * T0 * (T + T0))
    dsin = H * s * g / (T * T0)
    return dasinh_w, dT_w, dinv, dsin


def _shape(H: float, V0: float, s: np.ndarray, es: float, w: float) -> tuple[np.ndarray, ...]:
    """x(s), z(s) of the cable [m]."""
    dasinh_w, dT_w, _, _ = _terms(H, V0, s, w)
    return H * s / es + H * dasinh_w, (V0 * s + 0.5 * w * s * s) / es + dT_w


def _g_scalar(x: float, y: float) -> float:
    """:func:`_g` for two floats (the Newton loop's hot path)."""
    a, b = math.hypot(1.0, x), math.hypot(1.0, y)
    ap, am = (a + x, 1.0 / (a + x)) if x >= 0 else (1.0 / (a - x), a - x)
    bp, bm = (b + y, 1.0 / (b + y)) if y >= 0 else (1.0 / (b - y), b - y)
    return (am + bm) * (ap + bp) / (2.0 * (a + b))


def _residual(H: float, V0: float, l0: float, es: float, w: float) -> tuple[float, ...]:
    """x(L0), z(L0) and their (symmetric) Jacobian J00, J01 = J10, J11 wrt (H, V0)."""
    V = V0 + w * l0
    T, T0 = math.hypot(H, V), math.hypot(H, V0)
    g = _g_scalar(V / H, V0 / H)
    D = w * l0 / H * g
    dasinh_w = l0 * g / H * (math.asinh(D) / D if abs(D) >= 1e-6 else 1.0 - D * D / 6.0)
    dT_w = l0 * (V + V0) / (T + T0)
    dinv = -H * l0 * (V + V0) / (T * T0 * (T + T0))
    dsin = H * l0 * g / (T * T0)
    x = H * l0 / es + H * dasinh_w
    z = (V0 * l0 + 0.5 * w * l0 * l0) / es + dT_w
    return x, z, l0 / es + dasinh_w - dsin, dinv, l0 / es + dsin


def solve_catenary(
    l0: float, es: float, w: float, span_h: float, span_v: float, tol: float = 1e-11
) -> Catenary:
    """The hanging cable between two points.

    Args:
        l0: unstretched length L0 [m].
        es: axial stiffness E·S [N].
        w: weight per unstretched metre ρ g [N/m] (> 0).
        span_h: horizontal distance from the lower to the upper point [m] (> 0).
        span_v: height of the upper point above the lower one [m].
        tol: convergence tolerance on the end position [m].

    Returns:
        The solved :class:`Catenary`.

    Raises:
        CatenaryError: for a cable too long to be taut, or no convergence.
    """
    if not (l0 > 0 and es > 0 and w > 0 and span_h > 0):
        raise CatenaryError("need l0 > 0, es > 0, w > 0 and a horizontal span > 0")
    chord = math.hypot(span_h, span_v)
    tau = es * max(chord / l0 - 1.0, 1e-9) + 0.5 * w * l0  # straight elastic cable, a first guess
    H, V0 = tau * span_h / chord, tau * span_v / chord - 0.5 * w * l0
    for it in range(1, 101):
        x, z, j00, j01, j11 = _residual(H, V0, l0, es, w)
        ex, ez = x - span_h, z - span_v
        if max(abs(ex), abs(ez)) < tol:
            return Catenary(float(H), float(V0), l0, es, w, span_h, span_v, it)
        det = j00 * j11 - j01 * j01
        dH, dV = (-j11 * ex + j01 * ez) / det, (j01 * ex - j00 * ez) / det
        scale = 1.0
        while H + scale * dH <= 0:  # keep H positive (a taut span)
            scale *= 0.5
        H, V0 = H + scale * dH, V0 + scale * dV
    raise CatenaryError(f"no convergence (l0 = {l0} m, span {span_h}, {span_v} m)")


def end_forces(cat: Catenary, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cable's forces on its two ends in 3D (z up).

    Args:
        cat: the solved catenary between b (lower) and a (upper).
        a: (3,) upper point [m] (the pulley).
        b: (3,) lower point [m] (the platform's anchor).

    Returns:
        (force on b, force on a), each (3,) [N].
    """
    e = np.asarray(a, dtype=float)[:2] - np.asarray(b, dtype=float)[:2]
    e = e / np.linalg.norm(e)
    on_b = np.array([cat.horizontal * e[0], cat.horizontal * e[1], cat.vertical_low])
    on_a = -np.array([cat.horizontal * e[0], cat.horizontal * e[1], cat.vertical_high])
    return on_b, on_a
