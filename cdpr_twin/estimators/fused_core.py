"""The fused filter's per-update arithmetic, compiled with Numba.

An update of :mod:`cdpr_twin.estimators.fused` works on arrays of 3 to 88 elements, where
NumPy's per-call overhead (about a microsecond a call, a few hundred calls an update) outweighed
the arithmetic: 420–465 µs an update as the paper scenarios configure it. Here each stage —
prediction, cable readings, cable update, tag update — is one compiled call on the filter's
arrays. The equations are those of :mod:`cdpr_twin.estimators.fused_models` (the reference
formulations, NumPy, with ``tests/estimators/reference_fused.py``) and :mod:`cdpr_twin.math.se3`;
``tests/estimators/test_fused_core.py`` holds every function here to them (round-off apart: the
products are summed in another order).

The functions are compiled on first use and cached on disk (Numba's ``cache=True``, in
``__pycache__`` beside this file, or ``NUMBA_CACHE_DIR``): the first process to use them after
an install compiles them (16–20 s; :func:`warm_up` does it when the filter is built), later ones
load the machine code (≈ 0.2 s). The algebra is written as loops
(:mod:`~cdpr_twin.estimators.compiled_kernels`' ``mm``, ``inv``, …) rather than NumPy's ``@`` and
``np.linalg``: as fast at these sizes (84 against 94 µs an update), with no BLAS threads, and
the same numbers whichever BLAS NumPy was built with (it did not shorten the compilation,
measured 21 s either way). They release the GIL, so a camera's worker thread keeps running
beside them. The building blocks (SE(3) maps, the pulley
kernel, a detection's noise) are in :mod:`cdpr_twin.estimators.compiled_kernels`.

The layout (:class:`cdpr_twin.estimators.fused_models.Layout`) comes as ``blocks``, 7 ints
indexed by the constants below: the number of leading corrected states, then the first index of
each block (−1: the block is absent; exit and anchor points come together).
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.estimators.compiled_kernels import (
    add_to,
    adjoint,
    base_direction,
    condition_number,
    dot,
    indices,
    inv,
    inverse,
    jit,
    kernel,
    mm,
    mt,
    mv,
    put,
    scaled,
    se3_exp,
    se3_log,
    tag_noise,
    tm,
)

CABLES_USED, CABLES_NONE = 0, 1
"""``update_cables``'s outcomes: lengths fused; no usable cable."""
TAG_USED, TAG_ANCHORED, TAG_GATED = 0, 1, 2
"""``update_tag``'s outcomes: detection fused; the tag was anchored; detection gated out."""
CORRECTED, DRUM, EXIT, ANCHOR, CAM, INTR, TAG = range(7)
"""Indices into ``blocks``."""


# ------------------------------------------------------------------------------- Kalman
@jit
def joseph_update(
    P: np.ndarray, H: np.ndarray, R: np.ndarray, r: np.ndarray, c: int
) -> tuple[np.ndarray, float]:
    """Joseph-form update in place with the states from c on considered (Schmidt).

    P⁺ = P − K(HP) − (HP)ᵀKᵀ + K S Kᵀ on the leading c rows and columns (K's other rows are
    zero), the leading block symmetrised; the tests' ``reference_fused.joseph_update`` is the
    reference.

    Args:
        P: (n, n) covariance, symmetric; overwritten with the posterior.
        H: (k, n) measurement Jacobian.
        R: (k, k) measurement noise covariance.
        r: (k,) innovation.
        c: the number of leading corrected states.

    Returns:
        (c,) the corrected states' correction and the normalised innovation squared.
    """
    return joseph_update_hp(P, H, mm(H, P), R, r, c)


@jit
def joseph_update_hp(
    P: np.ndarray, H: np.ndarray, HP: np.ndarray, R: np.ndarray, r: np.ndarray, c: int
) -> tuple[np.ndarray, float]:
    """:func:`joseph_update` given HP = H P (k, n), for a caller that has it already."""
    S = add_to(mt(HP, H), R)
    S_inv = inv(S)
    # (c, k): the corrected states' rows only
    K = tm(HP[:, :c], S_inv)
    KHP = mm(K, HP)  # (c, n)
    KSK = mt(mm(K, S), K)
    n = P.shape[0]
    top = P[:c].copy()
    for i in range(c):
        for j in range(n):
            top[i, j] -= KHP[i, j]
        for j in range(c):
            top[i, j] += KSK[i, j] - KHP[j, i]
    for i in range(c):
        for j in range(i + 1):
            top[i, j] = top[j, i] = 0.5 * (top[i, j] + top[j, i])
    for i in range(c):
        for j in range(n):
            P[i, j] = top[i, j]
            P[j, i] = top[i, j]
    Sr = mv(S_inv, r)
    return mv(K, r), dot(r, Sr)


@jit
def moving(step: np.ndarray) -> bool:
    """Whether a step moves (``np.abs(step).max() > 0``: a NaN anywhere is no move)."""
    out = False
    for v in step:
        if v != v:
            return False
        out = out or v != 0.0
    return out


@jit
def transition(
    T: np.ndarray,
    step: np.ndarray,
    rates_dt: np.ndarray,
    hanging: np.ndarray,
    cables: np.ndarray,
    max_condition: float,
    blocks: np.ndarray,
    n: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The predicted pose T exp(ξΔt) (4, 4) and the transition's pose rows F (6, n).

    F's pose block is Ad(exp(−ξΔt)); while the hanging cables' Jacobian A is well conditioned
    (condition number ≤ ``max_condition``), the winches paying out (1 + ρ_i) l̇_i Δt move the
    platform by A⁺(ρ ⊙ l̇Δt) (drum columns) and the geometry errors by −A⁺ ΔG (∂L/∂(a, b) at
    the new pose minus at the old: exit and anchor columns). Arguments: see :func:`predict`.
    """
    E = se3_exp(step)
    T_new = mm(T, E)
    F = np.zeros((6, n))
    put(F, 0, 0, adjoint(inverse(E)))
    hang = indices(hanging)
    if len(hang) < 6 or not moving(step):
        return T_new, F
    _, rows = kernel(cables, T_new)
    A = np.empty((len(hang), 6))
    for j in range(len(hang)):
        for a in range(6):
            A[j, a] = rows[hang[j], a]
    if not condition_number(A) <= max_condition:
        return T_new, F
    A_pinv = mt(inv(tm(A, A)), A)  # (6, k)
    _, rows_prev = kernel(cables, T)
    exit0, anchor0 = blocks[EXIT], blocks[ANCHOR]
    for j in range(len(hang)):
        i = hang[j]
        for a in range(6):
            F[a, blocks[DRUM] + i] = A_pinv[a, j] * rates_dt[i]
        for b in range(3 if exit0 >= 0 else 0):  # −A⁺ G: this cable's exit and anchor columns
            g_exit = base_direction(rows_prev, T, i, b) - base_direction(rows, T_new, i, b)
            g_anchor = rows[i, b] - rows_prev[i, b]
            for a in range(6):
                F[a, exit0 + 3 * i + b] -= A_pinv[a, j] * g_exit
                F[a, anchor0 + 3 * i + b] -= A_pinv[a, j] * g_anchor
    return T_new, F


@jit
def predict(
    T: np.ndarray,
    P: np.ndarray,
    twist: np.ndarray,
    last_twist: np.ndarray,
    dt: float,
    rates: np.ndarray,
    hanging: np.ndarray,
    noise: np.ndarray,
    cables: np.ndarray,
    max_condition: float,
    blocks: np.ndarray,
) -> np.ndarray:
    """Propagate pose and covariance over one step: P ← F P Fᵀ + Q, in place.

    The step is ξΔt, the winches pay out l̇Δt, and Q = diag(q Δt + (τ_w |ξ − ξ_last|)²): the
    random walk and the winches' lag behind the change of command.

    Args:
        T: (4, 4) pose before the step.
        P: (n, n) covariance.
        twist: (6,) commanded platform twist ξ [m/s, rad/s] in F_p.
        last_twist: (6,) the previous step's ξ_last [m/s, rad/s].
        dt: Δt [s].
        rates: (m,) commanded winch rates l̇ [m/s].
        hanging: (m,) bool, the cables the platform hangs on.
        noise: (7,) τ_w [s], then the random walk's q per pose axis (6,) [m²/s, rad²/s].
        cables: (m, 7) :func:`~cdpr_twin.estimators.compiled_kernels.kernel`'s cables.
        max_condition: A's largest condition number for the drum and geometry columns.
        blocks: (7,) the layout.

    Returns:
        (4, 4) the predicted pose.
    """
    step, rates_dt, lag_var = scaled(twist, dt), scaled(rates, dt), np.empty(6)
    for i in range(6):
        lag = noise[0] * abs(twist[i] - last_twist[i])
        lag_var[i] = noise[1 + i] * dt + lag * lag
    n = P.shape[0]
    T_new, F = transition(T, step, rates_dt, hanging, cables, max_condition, blocks, n)
    X = mm(F, P)  # (6, n): F P, the new pose rows
    XF = mt(X, F)  # F P Fᵀ
    for i in range(6):
        for j in range(n):
            P[i, j] = P[j, i] = X[i, j]
    for i in range(6):
        for j in range(6):
            P[i, j] = 0.5 * (XF[i, j] + XF[j, i])
        P[i, i] += lag_var[i]
    return T_new


@jit
def cable_rows(
    T: np.ndarray,
    T0: np.ndarray,
    moved: np.ndarray,
    cables: np.ndarray,
    blocks: np.ndarray,
    n: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The cable readings' H (m, n) and model motions L(T) − L(T₀) (m,) [m].

    ∂/∂δ: the rows at T; ∂/∂δ₀: minus those at T₀; ∂/∂ρ_i: −Δl_i; ∂/∂a_i: R₀u₀ − Ru (F_b);
    ∂/∂b_i: u_p − u_p₀ (F_p). Arguments: see :func:`update_cables`.
    """
    m = cables.shape[0]
    l_now, rows_now = kernel(cables, T)
    l_0, rows_0 = kernel(cables, T0)
    H = np.zeros((m, n))
    exit0, anchor0 = blocks[EXIT], blocks[ANCHOR]
    for i in range(m):
        for a in range(6):
            H[i, a] = rows_now[i, a]
            H[i, 6 + a] = -rows_0[i, a]
        H[i, blocks[DRUM] + i] = -moved[i]
        for b in range(3 if exit0 >= 0 else 0):
            H[i, exit0 + 3 * i + b] = base_direction(rows_0, T0, i, b) - base_direction(
                rows_now, T, i, b
            )
            H[i, anchor0 + 3 * i + b] = rows_now[i, b] - rows_0[i, b]
    return H, l_now - l_0


@jit
def cable_readings(
    lengths: np.ndarray,
    tensions: np.ndarray,
    rates: np.ndarray,
    reference: np.ndarray,
    es: np.ndarray,
    noise: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The cable update's readings and their variances, from one measurement.

    ``fused_models``' :func:`~cdpr_twin.estimators.fused_models.corrected_readings` and
    :func:`~cdpr_twin.estimators.fused_models.cable_noise_var` (at tensions floored to 1e-9 N),
    element by element in one call.

    Args:
        lengths: (m,) encoder lengths [m].
        tensions: (m,) measured tensions [N].
        rates: (m,) commanded winch rates over the last period [m/s].
        reference: (2, m) the encoder lengths and the corrected readings at the reference [m].
        es: (m,) nominal E·S [N].
        noise: (5,) damping time η [s], encoder quantum q [m], the noise floor's std [m], a
            tension reading's std [N], the taut threshold [N].

    Returns:
        (3, m) :func:`update_cables`' ``readings`` (the corrected readings c, those of the
        reference c₀, the encoder counts since the reference Δl) [m], and (m,) their
        variances [m²].
    """
    eta, quantum, floor_std, tension_std, threshold = noise
    m = lengths.shape[0]
    readings, var = np.empty((3, m)), np.empty(m)
    floor = quantum**2 / 12.0 + floor_std**2
    for i in range(m):
        length, tension = lengths[i], tensions[i]
        readings[0, i] = length + length * tension / es[i] - eta * rates[i]
        readings[1, i] = reference[1, i]
        readings[2, i] = length - reference[0, i]
        elastic = length * tension_std / es[i]
        near_slack = max(3.0 * threshold / max(tension, 1e-9), 1.0)
        var[i] = (floor + 2.0 * elastic**2) * near_slack**4.0
    return readings, var


@jit
def update_cables(
    T: np.ndarray,
    T0: np.ndarray,
    P: np.ndarray,
    readings: np.ndarray,
    rho: np.ndarray,
    var: np.ndarray,
    taut: np.ndarray,
    cables: np.ndarray,
    half_quantum: float,
    gate: float,
    blocks: np.ndarray,
) -> tuple[int, bool, np.ndarray]:
    """Fuse the taut cables' readings since the reference (``fused_models``' cable model).

    y_i = c_i − c_i(t₀) (+ q/2 once the count moved) against h_i = L_i(T) − L_i(T₀) − ρ_i Δl_i;
    each taut cable's innovation is gated (χ²(1)) before the joint update. P: in place.

    Args:
        T: (4, 4) the pose.
        T0: (4, 4) the reference reading's pose.
        P: (n, n) covariance.
        readings: (3, m) the corrected readings c, those of the reference c₀, and the encoder
            counts since the reference Δl [m].
        rho: (m,) drum scale errors.
        var: (m,) reading variances [m²].
        taut: (m,) bool, the cables whose readings may be used.
        cables: (m, 7) :func:`~cdpr_twin.estimators.compiled_kernels.kernel`'s cables.
        half_quantum: half an encoder count [m].
        gate: the χ²(1) gate.
        blocks: (7,) the layout.

    Returns:
        (``CABLES_USED`` or ``CABLES_NONE``, whether a taut cable failed the gate, dx (c,)).
    """
    n, m, c = P.shape[0], cables.shape[0], blocks[CORRECTED]
    moved = readings[2]
    H, motion = cable_rows(T, T0, moved, cables, blocks, n)
    r = np.empty(m)
    for i in range(m):
        y = readings[0, i] - readings[1, i] + (half_quantum if moved[i] != 0.0 else 0.0)
        r[i] = y - (motion[i] - rho[i] * moved[i])
    HP = mm(H, P)
    use = np.zeros(m, dtype=np.bool_)
    outlier = False
    for i in range(m):
        gated = r[i] * r[i] > gate * (dot(HP[i], H[i]) + var[i])
        outlier = outlier or (gated and taut[i])
        use[i] = taut[i] and not gated
    idx = indices(use)
    k = len(idx)
    if k == 0:
        return CABLES_NONE, outlier, np.zeros(c)
    Hu, HPu, R, ru = np.empty((k, n)), np.empty((k, n)), np.zeros((k, k)), np.empty(k)
    for j in range(k):
        for a in range(n):
            Hu[j, a] = H[idx[j], a]
            # the gate's H P: the same rows, not computed again
            HPu[j, a] = HP[idx[j], a]
        R[j, j], ru[j] = var[idx[j]], r[idx[j]]
    return CABLES_USED, outlier, joseph_update_hp(P, Hu, HPu, R, ru, c)[0]


@jit
def anchor_tag(
    T: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    lag: np.ndarray,
    R: np.ndarray,
    calib: np.ndarray,
    T_platform_cam: np.ndarray,
    blocks: np.ndarray,
) -> np.ndarray:
    """Put the tag in F_b from the first detection, ᵇT_o = T exp(−ξd) ᵖT_c z: (4, 4).

    Its error δ_o = J x − n (J: the pose's, the mount's and the calibration's), so its rows of P
    are J P and its block J P Jᵀ + R (P in place). Arguments: see :func:`update_tag`.
    """
    n, tag0, cam0, intr0 = P.shape[0], blocks[TAG], blocks[CAM], blocks[INTR]
    M = mm(T_platform_cam, z)
    J = np.zeros((6, n))
    put(J, 0, 0, mm(adjoint(inverse(M)), adjoint(se3_exp(lag))))
    if cam0 >= 0:
        put(J, 0, cam0, adjoint(inverse(z)))
    if intr0 >= 0:
        put(J, 0, intr0, calib, -1.0)
    JP = mm(J, P)
    JPJ = mt(JP, J)
    for i in range(6):
        for j in range(n):
            P[tag0 + i, j] = P[j, tag0 + i] = JP[i, j]
    for i in range(6):
        for j in range(6):
            P[tag0 + i, tag0 + j] = 0.5 * (JPJ[i, j] + JPJ[j, i]) + R[i, j]
    return mm(mm(T, se3_exp(scaled(lag, -1.0))), M)


@jit
def update_tag(
    T: np.ndarray,
    T_tag: np.ndarray,
    anchored: bool,
    P: np.ndarray,
    z: np.ndarray,
    last_twist: np.ndarray,
    T_platform_cam: np.ndarray,
    options: np.ndarray,
    lens: np.ndarray,
    gate: float,
    blocks: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray]:
    """Fuse a tag detection z = ᶜT_o, or anchor the tag with the first one; P in place.

    The detection is the tag seen at T_lag = T exp(−ξd) (d the frame's age):
    z = T_pc⁻¹ T_lag⁻¹ ᵇT_o exp(n), n's covariance from the corners' pixel noise plus the lag's
    unmodelled motion; the innovation log(ẑ⁻¹ z) is gated (χ²(6)).

    Args:
        T: (4, 4) pose estimate.
        T_tag: (4, 4) the tag's pose in F_b (ignored until ``anchored``).
        anchored: whether the tag has been anchored.
        P: (n, n) covariance.
        z: (4, 4) the detection.
        last_twist: (6,) the last commanded twist [m/s, rad/s].
        T_platform_cam: (4, 4) the camera mounting.
        options: (5,) tag size [m], focal [px], pixel std [px], frame age d [s], τ_w [s].
        lens: (4,) the calibrated (k1, k2, p1, p2).
        gate: the χ²(6) gate.
        blocks: (7,) the layout.

    Returns:
        (outcome, (4, 4) the tag's pose, dx (c,): zeros unless ``TAG_USED``).
    """
    n, c, tag0, cam0, intr0 = P.shape[0], blocks[CORRECTED], blocks[TAG], blocks[CAM], blocks[INTR]
    R, calib = tag_noise(z, options[0], options[1], options[2], lens, intr0 >= 0)
    lag, tau = scaled(last_twist, options[3]), options[4]
    for i in range(6):
        R[i, i] += (tau * abs(last_twist[i])) ** 2 + 1e-12
    if not anchored:
        return TAG_ANCHORED, anchor_tag(T, P, z, lag, R, calib, T_platform_cam, blocks), np.zeros(c)
    M = mm(inverse(mm(T, se3_exp(scaled(lag, -1.0)))), T_tag)  # ᵖT_o at the frame's time
    z_hat = mm(inverse(T_platform_cam), M)
    r = se3_log(mm(inverse(z_hat), z))
    H = np.zeros((6, n))
    put(H, 0, 0, mm(adjoint(inverse(M)), adjoint(se3_exp(lag))), -1.0)
    for i in range(6):
        H[i, tag0 + i] = 1.0
    if cam0 >= 0:
        put(H, 0, cam0, adjoint(inverse(z_hat)), -1.0)
    if intr0 >= 0:
        put(H, 0, intr0, calib)
    S = add_to(mt(mm(H, P), H), R)
    if not dot(r, mv(inv(S), r)) <= gate:  # NaN (S singular) is gated out too
        return TAG_GATED, T_tag, np.zeros(c)
    return TAG_USED, T_tag, joseph_update(P, H, R, r, c)[0]


@jit
def inject(
    T: np.ndarray,
    T0: np.ndarray,
    T_tag: np.ndarray,
    rho: np.ndarray,
    dx: np.ndarray,
    blocks: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Apply a correction dx (c,): pose, start and tag on the right, drums (if corrected) added."""
    drum0, tag0 = blocks[DRUM], blocks[TAG]
    rho_new = rho.copy()
    if drum0 < dx.shape[0]:
        rho_new += dx[drum0 : drum0 + rho.shape[0]]
    return (
        mm(T, se3_exp(dx[0:6])),
        mm(T0, se3_exp(dx[6:12])),
        mm(T_tag, se3_exp(dx[tag0 : tag0 + 6])),
        rho_new,
    )


def warm_up(cables: np.ndarray, n: int, blocks: np.ndarray) -> None:
    """Call every stage once on made-up inputs of the filter's shapes and types.

    Compiles them (or loads them from the disk cache, ≈ 0.2 s) when the filter is built, not
    at its first update in the middle of a run, where a compilation (16–20 s, once after an
    install) would stall the loop and compete with the camera's worker thread.

    Args:
        cables: (m, 7) the filter's cables.
        n: the state's dimension.
        blocks: (7,) the layout.
    """
    m, c = cables.shape[0], int(blocks[CORRECTED])
    T = np.eye(4)
    T[:3, 3] = cables[:, :3].mean(axis=0) * 0.5 + np.array([0.0123, -0.0071, -0.2])
    P = np.eye(n) * 1e-6
    hanging = np.ones(m, dtype=bool)
    noise = np.full(7, 1e-9)
    predict(
        T, P, np.full(6, 0.03), np.zeros(6), 0.04, np.zeros(m), hanging, noise, cables, 1e12, blocks
    )
    update_cables(
        T,
        T,
        P,
        np.zeros((3, m)),
        np.zeros(m),
        np.full(m, 1e-6),
        hanging,
        cables,
        1e-5,
        1e300,
        blocks,
    )
    frozen = np.ones(m)
    # as a Measurement's (and its Command's) arrays
    frozen.flags.writeable = False
    cable_readings(frozen, frozen, frozen, np.ones((2, m)), np.ones(m), np.ones(5))
    z = np.eye(4)
    z[:3, 3] = [0.01, 0.02, 0.3]
    options, lens = np.array([0.04, 400.0, 1.0, 0.04, 0.008]), np.zeros(4)
    for anchored in (False, True):
        update_tag(T, T, anchored, P, z, np.zeros(6), T, options, lens, 1e300, blocks)
    inject(T, T, T, np.zeros(m), np.zeros(c), blocks)
