"""The fused filter's fast paths compute what the reference formulations compute, bit for bit.

:mod:`cdpr_twin.estimators.fused_fast` and :mod:`cdpr_twin.estimators.fused_fast_tag` redo
the per-update arithmetic of ``fused_models`` and ``se3`` with fewer NumPy calls; each is held
here to its reference on random inputs, byte for byte (signed zeros included).
"""

import numpy as np
import pytest

from cdpr_twin import se3
from cdpr_twin.estimators import fused_fast as ff
from cdpr_twin.estimators import fused_fast_tag as ft
from cdpr_twin.estimators import fused_models as fm


def same(a, b) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def random_pose(rng, scale=1.0):
    return se3.se3_exp(rng.normal(size=6) * scale)


def test_se3_helpers_are_bit_identical():
    rng = np.random.default_rng(1)
    for _ in range(2000):
        twist = rng.normal(size=6) * 10 ** rng.uniform(-9, 0.4)
        if rng.uniform() < 0.1:
            twist[3:] = 0.0
        T = se3.se3_exp(twist) @ random_pose(rng, 1e-3)
        assert same(ft.se3_log(T), se3.se3_log(T))
        assert same(ff.adjoint(T, invert=True), se3.adjoint(se3.inverse(T)))
        assert same(ff.adjoint(T), se3.adjoint(T))


def test_tag_noise_is_the_covariance_and_calibration_jacobian():
    rng = np.random.default_rng(2)
    for _ in range(300):
        R = se3.so3_exp(rng.normal(size=3) * 0.5)
        T = se3.transform(R, np.array([*rng.normal(size=2) * 0.05, rng.uniform(0.08, 0.6)]))
        lens = tuple(rng.normal(size=4) * [0.2, 0.08, 0.002, 0.002])
        cov, M = ft.tag_noise(T, 0.04, 415.69, 1.3, lens)
        assert same(cov, fm.tag_covariance(T, 0.04, 415.69, 1.3))
        assert same(M, fm.tag_calibration_jacobian(T, 0.04, 415.69, lens))
        assert ft.tag_noise(T, 0.04, 415.69, 1.3, lens, calibration=False)[1] is None


@pytest.mark.parametrize("x", [0.0, -0.0, 1e-300, -0.3, 0.3, 2.5, -1e50])
@pytest.mark.parametrize("y", [0.0, -0.0, -1e-300, 0.3, -0.3, 1e50])
def test_the_zero_lens_is_the_constant_pinhole(x, y):
    assert same(ft._lens_pixels([(x, y)] * 4, (0.0,) * 4, 415.69)[0], ft._pinhole(415.69))


def test_tag_residual_is_the_reference():
    rng = np.random.default_rng(3)
    T_pc = random_pose(rng, 0.1)
    for _ in range(300):
        T, T_tag, z = random_pose(rng), random_pose(rng), random_pose(rng, 0.3)
        lag = rng.normal(size=6) * 1e-3
        got = ft.tag_residual(T, T_tag, se3.inverse(T_pc), z, lag.tolist())
        for a, b in zip(got, fm.tag_residual(T, T_tag, T_pc, z, lag), strict=True):
            assert same(a, b)


@pytest.mark.parametrize(("n", "k", "c"), [(88, 8, 18), (88, 6, 18), (26, 5, 18), (12, 1, 12)])
def test_the_in_place_joseph_update_is_the_reference(n, k, c):
    """P symmetric but in its leading c × c block, as the filter keeps it."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        A = rng.normal(size=(n, n))
        P = A @ A.T + 1e-6 * np.eye(n)
        P[c:, c:] = np.diag(rng.uniform(size=n - c))
        P[:c, :c] += 1e-9 * rng.normal(size=(c, c))
        H, r = rng.normal(size=(k, n)), rng.normal(size=k)
        B = rng.normal(size=(k, k))
        R = B @ B.T + 0.1 * np.eye(k)
        dx, P_ref, _ = fm.joseph_update(P, H, R, r, c)
        P_fast = P.copy()
        assert same(ff.joseph_update_in_place(P_fast, H, R, r, c), dx[:c])
        assert not dx[c:].any()
        assert same(P_fast, P_ref)


@pytest.mark.parametrize("geometry", [True, False])
def test_cable_columns_build_the_reference_jacobians(geometry):
    rng = np.random.default_rng(5)
    layout = fm.Layout.build(8, geometry, True, True, True)
    columns = ff.CableColumns(layout, 8)
    for _ in range(300):
        rows, rows_0 = rng.normal(size=(8, 6)), rng.normal(size=(8, 6))
        rows[rng.uniform(size=(8, 6)) < 0.05] = -0.0
        rows_0[rng.uniform(size=(8, 6)) < 0.05] = 0.0
        R, R_0 = random_pose(rng)[:3, :3], random_pose(rng)[:3, :3]
        moved = rng.normal(size=8)
        moved[rng.uniform(size=8) < 0.3] = 0.0
        H = np.zeros((8, layout.n))  # as the filter built it before
        H[:, fm.POSE], H[:, fm.START], H[:, layout.drum] = rows, -rows_0, -np.diag(moved)
        H += fm.geometry_rows(layout, rows, R)
        H -= fm.geometry_rows(layout, rows_0, R_0)
        assert same(columns.measurement(rows, R, rows_0, R_0, moved.tolist()), H)
        if geometry:
            G = fm.geometry_rows(layout, rows, R) - fm.geometry_rows(layout, rows_0, R_0)
            assert same(columns.transition(rows, R, rows_0, R_0), G)


def test_cable_readings_noise_and_innovations_are_the_reference():
    rng = np.random.default_rng(6)
    es = rng.uniform(3e3, 5e3, size=8)
    for _ in range(500):
        lengths, rates = rng.uniform(0.3, 1.2, size=8), rng.normal(size=8) * 0.05
        tensions = rng.uniform(0.5, 40.0, size=8) if rng.uniform() < 0.5 else rng.uniform(5, 40, 8)
        args = (lengths.tolist(), tensions.tolist(), rates.tolist(), es.tolist(), 5e-4)
        c = fm.corrected_readings(lengths, tensions, rates, es, 5e-4)
        assert same(ff.corrected_readings(*args), c)
        noise = (3e-5, 2e-6, 0.24, 1.0)
        ref = fm.cable_noise_var(lengths, np.maximum(tensions, 1e-9), es, *noise)
        assert same(
            ff.cable_noise_var(lengths.tolist(), tensions.tolist(), es.tolist(), *noise), ref
        )
        ref_lengths, c_0, rho = lengths + rng.normal(size=8) * 1e-3, c - 1e-3, rng.normal(size=8)
        L, L_0 = rng.uniform(0.3, 1.2, size=8), rng.uniform(0.3, 1.2, size=8)
        moved = lengths - ref_lengths
        moved[rng.uniform(size=8) < 0.3] = 0.0
        y = c - c_0 + np.where(moved != 0.0, 0.5 * 3e-5, 0.0)  # as the filter computed it
        h = np.subtract(L, L_0) - rho * moved
        got = ff.cable_innovations(
            c.tolist(), c_0.tolist(), moved.tolist(), L.tolist(), L_0.tolist(), rho.tolist(), 3e-5
        )
        assert same(got, y - h)


def test_taut_cables_and_the_cable_gate_are_the_reference():
    rng = np.random.default_rng(7)
    for _ in range(300):
        tensions = rng.uniform(-1.0, 5.0, size=8)
        clipped = rng.uniform(size=8) < 0.2
        ref = tensions > 1.0
        assert ff.taut(tensions, None, 1.0) == ref.tolist()
        assert ff.taut(tensions, clipped, 1.0) == (ref & ~clipped).tolist()
        r, s, var = (
            rng.normal(size=8) * 1e-3,
            rng.uniform(size=8) * 1e-7,
            rng.uniform(size=8) * 1e-7,
        )
        taut = (ref & ~clipped).tolist()
        gated = r**2 > 15.1 * (s + var)  # as the filter computed it
        outlier, use = ff.gate_cables(r.tolist(), s.tolist(), var.tolist(), 15.1, taut)
        assert outlier == bool(np.any(gated & taut))
        assert use == np.flatnonzero(taut & ~gated).tolist()
