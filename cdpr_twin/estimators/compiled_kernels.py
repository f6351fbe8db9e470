"""Compiled building blocks of the fused filter: SE(3) maps, the pulley kernel, a detection's noise.

Numba versions of :mod:`cdpr_twin.math.se3`, :func:`cdpr_twin.math.kinematics.lengths_and_jacobian`
and
:func:`~cdpr_twin.estimators.fused_models.tag_calibration_jacobian` and the detection's noise
covariance (the references, NumPy: ``fused_models`` and ``tests/estimators/reference_fused.py``),
for :mod:`cdpr_twin.estimators.fused_core`; ``tests/estimators/test_fused_core.py`` holds each
to its reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cdpr_twin.math.se3 import _SERIES, _SMALL
from cdpr_twin.math.se3 import exp_coefficients as exp_coefficients_py

jit = njit(cache=True, nogil=True)
"""Compile, cache on disk, release the GIL."""


# ---------------------------------------------------------------------------------- SE(3)
exp_coefficients = jit(exp_coefficients_py)
"""``se3.exp_coefficients``, compiled: a = sin θ/θ, b = (1 − cos θ)/θ², c = (θ − sin θ)/θ³."""


@jit
def se3_exp(d: np.ndarray) -> np.ndarray:
    """Exponential of a twist d = [v, ω] (6,): (4, 4)."""
    wx, wy, wz = d[3], d[4], d[5]
    th2 = wx * wx + wy * wy + wz * wz
    a, b, c = exp_coefficients(th2)
    K = np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])
    K2 = mm(K, K)
    T = np.eye(4)
    for i in range(3):
        for j in range(3):
            T[i, j] += a * K[i, j] + b * K2[i, j]
        for j in range(3):
            T[i, 3] += ((i == j) + b * K[i, j] + c * K2[i, j]) * d[j]
    return T


@jit
def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4)."""
    out = np.eye(4)
    for i in range(3):
        for j in range(3):
            out[i, j] = T[j, i]
        out[i, 3] = -(T[0, i] * T[0, 3] + T[1, i] * T[1, 3] + T[2, i] * T[2, 3])
    return out


@jit
def se3_log(T: np.ndarray) -> np.ndarray:
    """Logarithm of a rigid transform (θ < π): (6,) ``[v, ω]`` (Shepperd's quaternion, w ≥ 0)."""
    r00, r01, r02 = T[0, 0], T[0, 1], T[0, 2]
    r10, r11, r12 = T[1, 0], T[1, 1], T[1, 2]
    r20, r21, r22 = T[2, 0], T[2, 1], T[2, 2]
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(1.0 + tr)
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(1.0 - r00 + r11 - r22)
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 - r00 - r11 + r22)
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    f = (-1.0 if w < 0.0 else 1.0) / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * f, x * f, y * f, z * f
    sv = math.sqrt(x * x + y * y + z * z)
    g = 2.0 / w if sv < _SMALL else 2.0 * math.atan2(sv, w) / sv  # θu = 2v to first order
    out = np.empty(6)
    out[3], out[4], out[5] = g * x, g * y, g * z
    theta2 = out[3] * out[3] + out[4] * out[4] + out[5] * out[5]
    if theta2 < _SERIES:
        dd = 1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    else:
        theta = math.sqrt(theta2)
        dd = (1.0 - theta * math.sin(theta) / (2.0 * (1.0 - math.cos(theta)))) / theta2
    K = np.array([[0.0, -out[5], out[4]], [out[5], 0.0, -out[3]], [-out[4], out[3], 0.0]])
    K2 = mm(K, K)
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += ((i == j) - 0.5 * K[i, j] + dd * K2[i, j]) * T[j, 3]
        out[i] = acc
    return out


@jit
def adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint (6, 6) of T for ``[v, ω]`` twists: [[R, [t]×R], [0, R]]."""
    Ad = np.zeros((6, 6))
    x, y, z = T[0, 3], T[1, 3], T[2, 3]
    for j in range(3):
        for i in range(3):
            Ad[i, j] = Ad[i + 3, j + 3] = T[i, j]
        Ad[0, j + 3] = -z * T[1, j] + y * T[2, j]
        Ad[1, j + 3] = z * T[0, j] - x * T[2, j]
        Ad[2, j + 3] = -y * T[0, j] + x * T[1, j]
    return Ad


# ------------------------------------------------------------------------------ the cables
@jit
def kernel(cables: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pulley lengths (eq. 15-24) and platform-frame Jacobian rows ``[u_p, b × u_p]``.

    Args:
        cables: (m, 7) per cable ``(ax, ay, az, bx, by, bz, r)``: exit point in F_b, anchor
            point in F_p, sheave radius [m] (0: a point exit, eq. 7).
        T: (4, 4) platform pose.

    Returns:
        (m,) lengths [m] and (m, 6) rows.
    """
    m = cables.shape[0]
    lengths, rows = np.empty(m), np.empty((m, 6))
    for i in range(m):
        ax, ay, az, px, py, pz, r = cables[i]
        lx = T[0, 0] * px + T[0, 1] * py + T[0, 2] * pz + T[0, 3] - ax
        ly = T[1, 0] * px + T[1, 1] * py + T[1, 2] * pz + T[1, 3] - ay
        lz = T[2, 0] * px + T[2, 1] * py + T[2, 2] * pz + T[2, 3] - az
        if r > 0.0:
            h = math.sqrt(lx * lx + ly * ly)
            cx, cy = lx / h, ly / h  # x_i (eq. 20-22)
            mx, my, mz = lx - r * cx, ly - r * cy, lz  # m_i = b_i − n_i (eq. 21, 23)
            mn = math.sqrt(mx * mx + my * my + mz * mz)
            free = math.sqrt(mn * mn - r * r)  # eq. 24
            lengths[i] = free + r * (math.pi - math.atan2(free, r) - math.asin(-mz / mn))
            eh, ez = (mx * cx + my * cy) / mn, mz / mn
            cp, sp = r / mn, free / mn
            ch, cz = r * (cp * eh + sp * ez), r * (cp * ez - sp * eh)  # tangent point − n_i
            ux, uy, uz = (mx - ch * cx) / free, (my - ch * cy) / free, (mz - cz) / free
        else:
            lengths[i] = math.sqrt(lx * lx + ly * ly + lz * lz)
            ux, uy, uz = lx / lengths[i], ly / lengths[i], lz / lengths[i]
        vx = T[0, 0] * ux + T[1, 0] * uy + T[2, 0] * uz  # u_p = Rᵀ u
        vy = T[0, 1] * ux + T[1, 1] * uy + T[2, 1] * uz
        vz = T[0, 2] * ux + T[1, 2] * uy + T[2, 2] * uz
        rows[i, 0], rows[i, 1], rows[i, 2] = vx, vy, vz
        rows[i, 3], rows[i, 4], rows[i, 5] = py * vz - pz * vy, pz * vx - px * vz, px * vy - py * vx
    return lengths, rows


@jit
def base_direction(rows: np.ndarray, T: np.ndarray, i: int, a: int) -> float:
    """Component a of cable i's direction in F_b, R u_p."""
    return T[a, 0] * rows[i, 0] + T[a, 1] * rows[i, 1] + T[a, 2] * rows[i, 2]


# ---------------------------------------------------------------------------------- tag
@jit
def tag_noise(
    z: np.ndarray,
    tag_size: float,
    focal_px: float,
    pixel_std: float,
    lens: np.ndarray,
    calibration: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """A detection's noise covariance (6, 6) and calibration Jacobian ∂n/∂δk (6, 8).

    ``reference_fused.tag_covariance`` (pinhole) and ``tag_calibration_jacobian`` (through the
    calibrated lens (k1, k2, p1, p2)); the Jacobian is zeros when ``calibration`` is False.
    """
    h = 0.5 * tag_size
    corners = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    k1, k2, p1, p2 = lens[0], lens[1], lens[2], lens[3]
    J = np.empty((8, 6))  # pinhole pixels per tag-frame twist
    Jl = np.empty((8, 6))  # the same through the lens
    Pi = np.zeros((8, 8))  # pixels per (fx, fy, cx, cy, k1, k2, p1, p2)
    for q in range(4):
        px, py = corners[q, 0], corners[q, 1]
        X = z[0, 0] * px + z[0, 1] * py + z[0, 3]
        Y = z[1, 0] * px + z[1, 1] * py + z[1, 3]
        Z = z[2, 0] * px + z[2, 1] * py + z[2, 3]
        inv_z = 1.0 / Z
        x, y = X * inv_z, Y * inv_z
        dn = np.array([[inv_z, 0.0, -inv_z * x], [0.0, inv_z, -inv_z * y]])  # d(x, y)/dX
        dp = np.empty((3, 6))  # dX/d[v, ω] = R [I, −[p]×], p = (px, py, 0)
        for a in range(3):
            dp[a, 0], dp[a, 1], dp[a, 2] = z[a, 0], z[a, 1], z[a, 2]
            dp[a, 3] = z[a, 2] * py
            dp[a, 4] = -z[a, 2] * px
            dp[a, 5] = -z[a, 0] * py + z[a, 1] * px
        G = mm(dn, dp)  # (2, 6)
        r2 = x * x + y * y
        aa, da = 1.0 + k1 * r2 + k2 * r2 * r2, 2.0 * k1 + 4.0 * k2 * r2
        d00 = aa + x * x * da + 2 * p1 * y + 6 * p2 * x
        d01 = x * y * da + 2 * p1 * x + 2 * p2 * y
        d11 = aa + y * y * da + 6 * p1 * y + 2 * p2 * x
        for b in range(6):
            J[2 * q, b] = focal_px * G[0, b]
            J[2 * q + 1, b] = focal_px * G[1, b]
            Jl[2 * q, b] = focal_px * (d00 * G[0, b] + d01 * G[1, b])
            Jl[2 * q + 1, b] = focal_px * (d01 * G[0, b] + d11 * G[1, b])
        Pi[2 * q, 0] = x * aa + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        Pi[2 * q + 1, 1] = y * aa + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        Pi[2 * q, 2] = Pi[2 * q + 1, 3] = 1.0
        Pi[2 * q, 4], Pi[2 * q, 5] = focal_px * x * r2, focal_px * x * r2 * r2
        Pi[2 * q, 6], Pi[2 * q, 7] = focal_px * 2 * x * y, focal_px * (r2 + 2 * x * x)
        Pi[2 * q + 1, 4], Pi[2 * q + 1, 5] = focal_px * y * r2, focal_px * y * r2 * r2
        Pi[2 * q + 1, 6], Pi[2 * q + 1, 7] = focal_px * (r2 + 2 * y * y), focal_px * 2 * x * y
    cov = pixel_std * pixel_std * inv(tm(J, J))
    if not calibration:
        return cov, np.zeros((6, 8))
    return cov, -mm(inv(tm(Jl, Jl)), tm(Jl, Pi))


# --------------------------------------------------------------------- small dense algebra
# Loops rather than NumPy's ``@`` and ``np.linalg`` on these sizes (≤ 88 × 88, solves ≤ 8):
# as fast, no BLAS threads, and the same numbers whichever BLAS NumPy was built with.
@jit
def put(dst: np.ndarray, i0: int, j0: int, src: np.ndarray, sign: float = 1.0) -> None:
    """``dst[i0:i0 + p, j0:j0 + q] = sign · src`` for a (p, q) ``src``, as a loop.

    A slice assignment compiles NumPy's broadcasting checks with their error messages (string
    formatting): over a third of the filter's one-time compilation. ``sign`` is ±1 (exact).
    """
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i0 + i, j0 + j] = sign * src[i, j]


@jit
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """The dot product of two (k,) vectors, summed in order (as ``np.sum(a * b)`` compiles)."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@jit
def scaled(v: np.ndarray, s: float) -> np.ndarray:
    """The (k,) vector s · v, new (an array expression compiles a kernel of its own)."""
    out = np.empty(v.shape[0])
    for i in range(v.shape[0]):
        out[i] = v[i] * s
    return out


@jit
def add_to(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A += B for two (p, q) matrices; returns A."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            A[i, j] += B[i, j]
    return A


@jit
def mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A B: (p, q) × (q, r) → (p, r)."""
    p, q, r = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((p, r))
    for i in range(p):
        for k in range(q):
            a = A[i, k]
            if a != 0.0:
                for j in range(r):
                    out[i, j] += a * B[k, j]
    return out


@jit
def mt(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A Bᵀ: (p, q) × (r, q) → (p, r)."""
    p, q, r = A.shape[0], A.shape[1], B.shape[0]
    out = np.empty((p, r))
    for i in range(p):
        for j in range(r):
            acc = 0.0
            for k in range(q):
                b = B[j, k]
                # B's zeros skipped, as mm skips A's: H and F rows are mostly zeros
                if b != 0.0:
                    acc += A[i, k] * b
            out[i, j] = acc
    return out


@jit
def tm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Aᵀ B: (q, p) × (q, r) → (p, r)."""
    return mm(np.ascontiguousarray(A.T), B)


@jit
def mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x: (p, q) × (q,) → (p,)."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            out[i] += A[i, k] * x[k]
    return out


@jit
def inv(A: np.ndarray) -> np.ndarray:
    """Inverse of a small square matrix, Gauss–Jordan with partial pivoting (NaN if singular)."""
    n = A.shape[0]
    M = A.copy()
    out = np.eye(n)
    for col in range(n):
        piv = col
        for i in range(col + 1, n):
            if abs(M[i, col]) > abs(M[piv, col]):
                piv = i
        if M[piv, col] == 0.0:
            return np.full((n, n), np.nan)
        for j in range(n):
            M[col, j], M[piv, j] = M[piv, j], M[col, j]
            out[col, j], out[piv, j] = out[piv, j], out[col, j]
        d = 1.0 / M[col, col]
        for j in range(n):
            M[col, j] *= d
            out[col, j] *= d
        for i in range(n):
            f = M[i, col]
            if i != col and f != 0.0:
                for j in range(n):
                    M[i, j] -= f * M[col, j]
                    out[i, j] -= f * out[col, j]
    return out


@jit
def condition_number(A: np.ndarray) -> float:
    """σ_max/σ_min of a (k, q) matrix, k ≥ q: √ of AᵀA's eigenvalue ratio (cyclic Jacobi).

    ∞ when A is rank-deficient. AᵀA's eigenvalues come out within ~ε·λ_max, so the ratio is
    right to a relative ~κ²ε: 1e-10 at κ = 10³ (the filter compares it with 500), 1e-8 at 3·10⁴.
    """
    q = A.shape[1]
    S = np.zeros((q, q))
    for i in range(q):
        for j in range(q):
            for k in range(A.shape[0]):
                S[i, j] += A[k, i] * A[k, j]
    for _ in range(50):
        off, diag = 0.0, 0.0
        for i in range(q):
            diag += S[i, i] * S[i, i]
            for j in range(i + 1, q):
                off += S[i, j] * S[i, j]
        if off <= 1e-32 * diag:
            break
        for p in range(q):
            for r in range(p + 1, q):
                if S[p, r] == 0.0:
                    continue
                theta = 0.5 * (S[r, r] - S[p, p]) / S[p, r]
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(q):  # S ← Jᵀ S J with the rotation in the (p, r) plane
                    skp, skr = S[k, p], S[k, r]
                    S[k, p], S[k, r] = c * skp - s * skr, s * skp + c * skr
                for k in range(q):
                    spk, srk = S[p, k], S[r, k]
                    S[p, k], S[r, k] = c * spk - s * srk, s * spk + c * srk
    lo, hi = S[0, 0], S[0, 0]
    for i in range(1, q):
        lo, hi = min(lo, S[i, i]), max(hi, S[i, i])
    return math.sqrt(hi / lo) if lo > 0.0 else math.inf


@jit
def indices(mask: np.ndarray) -> np.ndarray:
    """The indices of a bool mask's True entries (``np.flatnonzero``)."""
    out = np.empty(mask.shape[0], dtype=np.int64)
    k = 0
    for i in range(mask.shape[0]):
        if mask[i]:
            out[k] = i
            k += 1
    return out[:k]
