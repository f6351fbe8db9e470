"""The fused filter's compiled arithmetic computes what the reference formulations compute.

:mod:`cdpr_twin.estimators.fused_core` and :mod:`~cdpr_twin.estimators.compiled_kernels` redo,
compiled, the per-update arithmetic whose reference is ``reference_fused.py`` (beside this
file), :mod:`cdpr_twin.estimators.fused_models`, :mod:`cdpr_twin.math.se3` and
:func:`cdpr_twin.math.kinematics.lengths_and_jacobian` (NumPy). Each compiled stage is held here to
that reference on random and on ACROBOT's inputs, to round-off (the products are summed in
another order): the SE(3) maps, the pulley kernel (and its Jacobian against finite
differences), the Joseph update with considered states, the detection's noise and calibration
Jacobian, and the three stages of an update (prediction, cable update, tag update) with every
block of the layout present and without the optional ones.
"""

from pathlib import Path

import numpy as np
import pytest
import reference_fused as reference
from conftest import paper_pose

from cdpr_twin.estimators import compiled_kernels as fk
from cdpr_twin.estimators import fused_core as fc
from cdpr_twin.estimators import fused_models as fm
from cdpr_twin.math import se3
from cdpr_twin.math.kinematics import lengths_and_jacobian


def close(a, b, rel=1e-12) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.abs(a - b).max(initial=0.0) <= rel * max(
        np.abs(b).max(initial=0.0), 1e-300
    )


def random_pose(rng, scale=1.0):
    return se3.se3_exp(rng.normal(size=6) * scale)


def random_covariance(rng, n, scale=1e-4):
    A = rng.normal(size=(n, n)) * scale
    return A @ A.T + 1e-12 * np.eye(n)


def test_se3_maps_are_the_reference():
    rng = np.random.default_rng(1)
    for _ in range(1000):
        twist = rng.normal(size=6) * 10 ** rng.uniform(-9, 0.4)
        if rng.uniform() < 0.1:
            twist[3:] = 0.0
        T = se3.se3_exp(twist) @ random_pose(rng, 1e-3)
        assert close(fk.se3_exp(twist), se3.se3_exp(twist), 1e-14)
        assert close(fk.se3_log(T), se3.se3_log(T), 1e-12)
        assert close(fk.inverse(T), se3.inverse(T), 1e-14)
        assert close(fk.adjoint(T), se3.adjoint(T), 1e-14)


def test_the_kernel_is_the_pulley_model_and_its_rows_the_jacobian(twin):
    g = twin.nominal.geometry
    cables = np.column_stack([g.a_base, g.b_platform, g.pulley_radius])
    rng = np.random.default_rng(2)
    for T in [paper_pose("p0"), paper_pose("p1")] + [
        paper_pose("p1") @ random_pose(rng, 0.05) for _ in range(50)
    ]:
        lengths, rows = fk.kernel(cables, T)
        ref_lengths, ref_rows = lengths_and_jacobian(g.a_base, g.b_platform, g.pulley_radius, T)
        assert close(lengths, ref_lengths, 1e-14) and close(rows, ref_rows, 1e-13)
        straight = fk.kernel(np.column_stack([g.a_base, g.b_platform, np.zeros(8)]), T)
        ref_straight = lengths_and_jacobian(g.a_base, g.b_platform, None, T)
        assert close(straight[0], ref_straight[0], 1e-14)
        assert close(straight[1], ref_straight[1], 1e-13)
    h = 1e-6  # dL/dδ by central differences, δ a platform-frame twist
    fd = np.column_stack(
        [
            (
                fk.kernel(cables, T @ se3.se3_exp(h * e))[0]
                - fk.kernel(cables, T @ se3.se3_exp(-h * e))[0]
            )
            / (2 * h)
            for e in np.eye(6)
        ]
    )
    assert np.abs(fd - rows).max() < 1e-8


def test_the_small_dense_algebra_is_numpys():
    rng = np.random.default_rng(9)
    for p, q, r in ((6, 88, 88), (8, 88, 8), (3, 3, 3), (1, 6, 1)):
        A, B, C = rng.normal(size=(p, q)), rng.normal(size=(q, r)), rng.normal(size=(r, q))
        A[rng.uniform(size=A.shape) < 0.3] = 0.0  # the products skip zeros
        assert close(fk.mm(A, B), A @ B, 1e-13)
        assert close(fk.mt(A, C), A @ C.T, 1e-13)
        assert close(fk.tm(B, B), B.T @ B, 1e-13)
        assert close(fk.mv(A, B[:, 0].copy()), A @ B[:, 0], 1e-13)
    for k in (1, 6, 8):
        S = random_covariance(rng, k, 1.0) + 0.1 * np.eye(k)
        assert close(fk.inv(S), np.linalg.inv(S), 1e-10)
        G = rng.normal(size=(k, k))  # not symmetric: the pivoting matters
        assert close(fk.inv(G) @ G, np.eye(k), 1e-9)
    assert np.isnan(fk.inv(np.zeros((3, 3)))).all()


@pytest.mark.parametrize("target", [1.0, 18.0, 500.0, 3e4])
def test_the_condition_number_is_the_svds(target):
    rng = np.random.default_rng(10)
    U = np.linalg.qr(rng.normal(size=(8, 6)))[0]
    V = np.linalg.qr(rng.normal(size=(6, 6)))[0]
    A = U @ np.diag(np.geomspace(1.0, 1.0 / target, 6)) @ V.T
    sv = np.linalg.svd(A, compute_uv=False)
    # AᵀA squares κ: its smallest eigenvalue comes out within ~κ²ε (relative)
    assert fk.condition_number(A) == pytest.approx(sv[0] / sv[-1], rel=1e-9 + 1e-14 * target**2)
    A[:, 5] = A[:, 4]  # rank-deficient
    assert fk.condition_number(A) > 1e7


@pytest.mark.parametrize(("n", "k", "c"), [(88, 8, 18), (88, 6, 18), (26, 5, 18), (12, 1, 12)])
def test_the_joseph_update_is_the_reference(n, k, c):
    rng = np.random.default_rng(4)
    for _ in range(30):
        P = random_covariance(rng, n, 1.0)
        H, r = rng.normal(size=(k, n)), rng.normal(size=k)
        R = random_covariance(rng, k, 1.0) + 0.1 * np.eye(k)
        dx, P_ref, nis = reference.joseph_update(P, H, R, r, c)
        P_got = P.copy()
        got, got_nis = fc.joseph_update(P_got, H, R, r, c)
        assert close(got, dx[:c], 1e-10) and not dx[c:].any()
        assert close(P_got, P_ref, 1e-12)
        assert np.array_equal(P_got[c:, c:], P[c:, c:])  # the considered block is untouched
        assert np.array_equal(P_got, P_got.T)
        assert got_nis == pytest.approx(nis, rel=1e-10)


def test_the_detection_noise_and_calibration_jacobian_are_the_reference():
    rng = np.random.default_rng(2)
    for _ in range(300):
        R = se3.so3_exp(rng.normal(size=3) * 0.5)
        z = se3.transform(R, np.array([*rng.normal(size=2) * 0.05, rng.uniform(0.08, 0.6)]))
        lens = rng.normal(size=4) * [0.2, 0.08, 0.002, 0.002]
        cov, M = fk.tag_noise(z, 0.04, 415.69, 1.3, lens, True)
        assert close(cov, reference.tag_covariance(z, 0.04, 415.69, 1.3), 1e-9)
        assert close(M, fm.tag_calibration_jacobian(z, 0.04, 415.69, lens), 1e-9)
        assert not fk.tag_noise(z, 0.04, 415.69, 1.3, lens, False)[1].any()


@pytest.fixture(params=[True, False], ids=["every-block", "pose-start-tag-drums"])
def layout(request):
    full = request.param
    return fm.Layout.build(8, full, full, True, full)


def _blocks(layout):
    def first(block):
        return block.start if block.stop > block.start else -1

    L = layout
    return np.array(
        [
            L.corrected,
            L.drum.start,
            first(L.exit),
            first(L.anchor),
            first(L.cam),
            first(L.intr),
            L.tag.start,
        ]
    )


def _geometry_columns(layout, rows, T):
    return reference.geometry_rows(layout, rows, T[:3, :3])


@pytest.mark.parametrize("conditioned", [True, False])
def test_the_prediction_is_the_reference_transition(twin, layout, conditioned):
    """P⁺ = F P Fᵀ + Q with F = I but its pose rows: Ad(exp(−ξΔt)), A⁺(ρ⊙l̇Δt) in the drum
    columns and −A⁺ΔG in the geometry's, A the hanging cables' rows at the new pose."""
    g = twin.nominal.geometry
    cables = np.column_stack([g.a_base, g.b_platform, g.pulley_radius])
    blocks = _blocks(layout)
    rng = np.random.default_rng(5)
    for trial in range(10):
        T = paper_pose("p1") @ random_pose(rng, 0.02)
        P = random_covariance(rng, layout.n)
        dt = 0.04
        twist, last_twist = rng.normal(size=(2, 6)) * 0.025
        rates = rng.normal(size=8) * 0.025
        hanging = np.ones(8, dtype=bool)
        hanging[rng.choice(8, size=trial % 3, replace=False)] = False
        tau, q = 0.008, rng.uniform(size=6) * 1e-7
        max_condition = 1e9 if conditioned else 1.0
        P_got = P.copy()
        noise = np.array([tau, *q])
        T_got = fc.predict(
            T, P_got, twist, last_twist, dt, rates, hanging, noise, cables, max_condition, blocks
        )
        # the random walk's q·Δt, and the winches' lag τ_w behind the change of command
        step, rates_dt = twist * dt, rates * dt
        lag_var = q * dt + (tau * np.abs(twist - last_twist)) ** 2
        T_new = T @ se3.se3_exp(step)
        F = np.eye(layout.n)
        F[:6, :6] = se3.adjoint(se3.inverse(se3.se3_exp(step)))
        if conditioned:
            rows = lengths_and_jacobian(g.a_base, g.b_platform, g.pulley_radius, T_new)[1]
            rows_prev = lengths_and_jacobian(g.a_base, g.b_platform, g.pulley_radius, T)[1]
            A_pinv = np.linalg.pinv(rows[hanging])
            drums = np.flatnonzero(hanging) + layout.drum.start
            F[:6, drums] = A_pinv * rates_dt[hanging]
            G = _geometry_columns(layout, rows, T_new) - _geometry_columns(layout, rows_prev, T)
            F[:6] -= A_pinv @ G[hanging]
        P_ref = F @ P @ F.T
        P_ref[:6, :6] += np.diag(lag_var)
        assert close(T_got, T_new, 1e-14)
        assert close(P_got, P_ref, 1e-10)
        assert np.array_equal(P_got[6:, 6:], P[6:, 6:])


def test_the_cable_readings_are_the_models_formulas():
    """Row 0 c = l + lτ/E·S − ηl̇, row 1 c₀, row 2 Δl = l − l₀; the variances those of
    ``fused_models`` (floored tension, slack-prone cables trusted less): to an ulp or two."""
    rng = np.random.default_rng(8)
    eta, quantum, floor_std, tension_std, threshold = 5e-4, 3e-5, 2e-6, 0.01, 1.0
    noise = np.array([eta, quantum, floor_std, tension_std, threshold])
    es = rng.uniform(2e4, 8e4, 8)
    for _ in range(50):
        lengths, rates = rng.uniform(0.5, 1.2, 8), rng.normal(size=8) * 0.05
        tensions = rng.uniform(-1.0, 40.0, 8)  # slack, near slack and taut
        for a in (lengths, tensions, rates):
            a.flags.writeable = False  # as a Measurement's arrays (one compiled signature)
        reference = rng.uniform(0.5, 1.2, (2, 8))
        readings, var = fc.cable_readings(lengths, tensions, rates, reference, es, noise)
        corrected = fm.corrected_readings(lengths, tensions, rates, es, eta)
        np.testing.assert_allclose(readings[0], corrected, rtol=1e-15)
        assert np.array_equal(readings[1], reference[1])
        assert np.array_equal(readings[2], lengths - reference[0])
        expected = fm.cable_noise_var(
            lengths, tensions, es, quantum, floor_std, tension_std, threshold
        )
        np.testing.assert_allclose(var, expected, rtol=1e-14)


def test_the_cable_update_is_the_reference(twin, layout):
    """y = c − c₀ (+ q/2 once moved) against h = L(T) − L(T₀) − ρΔl, gated per cable (χ²(1)),
    then one Joseph update of the taut cables that passed."""
    g = twin.nominal.geometry
    cables = np.column_stack([g.a_base, g.b_platform, g.pulley_radius])
    blocks = _blocks(layout)
    c = layout.corrected
    rng = np.random.default_rng(6)
    used = 0
    for _ in range(20):
        T0 = paper_pose("p0") @ random_pose(rng, 1e-3)
        T = paper_pose("p0") @ random_pose(rng, 0.01)
        P = random_covariance(rng, layout.n)
        corrected, corrected_0 = rng.uniform(0.5, 1.2, 8), rng.uniform(0.5, 1.2, 8)
        moved = rng.normal(size=8) * 0.01
        moved[rng.uniform(size=8) < 0.3] = 0.0
        rho, var = rng.normal(size=8) * 0.005, rng.uniform(1e-10, 1e-8, 8)
        taut = rng.uniform(size=8) < 0.8
        l_now, rows_now = lengths_and_jacobian(g.a_base, g.b_platform, g.pulley_radius, T)
        l_0, rows_0 = lengths_and_jacobian(g.a_base, g.b_platform, g.pulley_radius, T0)
        corrected = corrected_0 + (l_now - l_0) + rng.normal(size=8) * 1e-4  # a few gated
        H = np.zeros((8, layout.n))
        H[:, fm.POSE], H[:, fm.START], H[:, layout.drum] = rows_now, -rows_0, -np.diag(moved)
        H += _geometry_columns(layout, rows_now, T) - _geometry_columns(layout, rows_0, T0)
        y = corrected - corrected_0 + np.where(moved != 0.0, 1e-5, 0.0)
        r = y - ((l_now - l_0) - rho * moved)
        gated = r**2 > 15.1 * (np.einsum("ij,jk,ik->i", H, P, H) + var)
        use = taut & ~gated
        P_got = P.copy()
        readings = np.array([corrected, corrected_0, moved])
        outcome, outlier, dx = fc.update_cables(
            T, T0, P_got, readings, rho, var, taut, cables, 1e-5, 15.1, blocks
        )
        assert outlier == bool((gated & taut).any())
        if not use.any():
            assert outcome == fc.CABLES_NONE and np.array_equal(P_got, P)
            continue
        used += 1
        dx_ref, P_ref, _ = reference.joseph_update(P, H[use], np.diag(var[use]), r[use], c)
        assert outcome == fc.CABLES_USED
        assert close(dx, dx_ref[:c], 1e-9) and close(P_got, P_ref, 1e-10)
    assert used >= 10


def test_the_tag_update_and_anchoring_are_the_reference(layout):
    rng = np.random.default_rng(7)
    blocks = _blocks(layout)
    cam0 = blocks[fc.CAM]
    c, t = layout.corrected, layout.tag
    T_pc = random_pose(rng, 0.1)
    lens = np.array([-0.2, 0.08, 0.002, -0.002])
    options = np.array([0.04, 415.69, 1.0, 0.044, 0.008])
    gate = fm.chi2_gate(6, 0.9999)
    fused = 0
    for _ in range(20):
        T, last = random_pose(rng, 0.3), rng.normal(size=6) * 0.02
        z = se3.transform(se3.so3_exp(rng.normal(size=3) * 0.2), np.array([0.01, -0.02, 0.4]))
        lag = last * options[3]
        R = reference.tag_covariance(z, 0.04, 415.69, 1.0)
        R += np.diag((options[4] * np.abs(last)) ** 2 + 1e-12)
        calib = fm.tag_calibration_jacobian(z, 0.04, 415.69, lens)
        # anchoring: ᵇT_o = T exp(−ξd) ᵖT_c z, its rows J P, its block J P Jᵀ + R
        P = random_covariance(rng, layout.n)
        P[t, :] = P[:, t] = 0.0
        P_got = P.copy()
        outcome, T_tag, _ = fc.update_tag(
            T, np.eye(4), False, P_got, z, last, T_pc, options, lens, gate, blocks
        )
        assert outcome == fc.TAG_ANCHORED
        M = T_pc @ z
        assert close(T_tag, T @ se3.se3_exp(-lag) @ M, 1e-14)
        J = np.zeros((6, layout.n))
        J[:, fm.POSE] = se3.adjoint(se3.inverse(M)) @ se3.adjoint(se3.se3_exp(lag))
        if cam0 >= 0:
            J[:, layout.cam], J[:, layout.intr] = se3.adjoint(se3.inverse(z)), -calib
        P_ref = P.copy()
        P_ref[t, :] = J @ P
        P_ref[:, t] = P_ref[t, :].T
        P_ref[t, t] = J @ P @ J.T + R
        assert close(P_got, P_ref, 1e-9)
        # a later detection, near what the anchored tag predicts, after the pose's uncertainty
        # grew (at the anchoring pose and covariance it would say nothing of the pose)
        z2 = z @ se3.se3_exp(rng.normal(size=6) * 1e-3)
        P_got[:6, :6] += np.diag(rng.uniform(1e-8, 1e-6, 6))
        P2 = P_got.copy()
        R = reference.tag_covariance(z2, 0.04, 415.69, 1.0)
        R += np.diag((options[4] * np.abs(last)) ** 2 + 1e-12)
        calib = fm.tag_calibration_jacobian(z2, 0.04, 415.69, lens)
        outcome, _, dx = fc.update_tag(
            T, T_tag, True, P2, z2, last, T_pc, options, lens, gate, blocks
        )
        r, H_pose, z_hat = reference.tag_residual(T, T_tag, T_pc, z2, lag)
        H = np.zeros((6, layout.n))
        H[:, fm.POSE], H[:, t] = H_pose, np.eye(6)
        if cam0 >= 0:
            H[:, layout.cam] = -se3.adjoint(se3.inverse(z_hat))
            H[:, layout.intr] = calib
        S = H @ P_got @ H.T + R
        if r @ np.linalg.solve(S, r) > gate:
            assert outcome == fc.TAG_GATED and np.array_equal(P2, P_got)
            continue
        dx_ref, P_ref, _ = reference.joseph_update(P_got, H, R, r, c)
        assert outcome == fc.TAG_USED
        assert close(dx, dx_ref[:c], 1e-8) and close(P2, P_ref, 1e-9)
        fused += 1
    assert fused >= 10


def test_injection_composes_on_the_right_and_adds_corrected_drums():
    rng = np.random.default_rng(8)
    T, T0, T_tag = random_pose(rng), random_pose(rng), random_pose(rng)
    rho = rng.normal(size=8) * 1e-3
    for c, drums_corrected in ((18, False), (26, True)):
        dx = rng.normal(size=c) * 1e-3
        blocks = np.array([c, 18, -1, -1, -1, -1, 12])
        got = fc.inject(T, T0, T_tag, rho, dx, blocks)
        assert close(got[0], T @ se3.se3_exp(dx[:6]), 1e-14)
        assert close(got[1], T0 @ se3.se3_exp(dx[6:12]), 1e-14)
        assert close(got[2], T_tag @ se3.se3_exp(dx[12:18]), 1e-14)
        assert close(got[3], rho + dx[18:26] if drums_corrected else rho, 1e-15)


def test_a_run_uses_the_signatures_the_filter_compiled_when_built(tmp_path):
    """Each stage has one compiled signature, the warm-up's (at construction): a run's inputs
    (read-only measurement arrays, the geometry's frozen mount) reach it as the same types, so
    nothing is compiled in the middle of a run."""
    from cdpr_twin.run.runner import run
    from cdpr_twin.scenario.loading import load_scenario

    ROOT = Path(__file__).resolve().parents[2]
    s = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml").with_overrides(duration=0.5)
    assert "fused" in s.estimators.passive or s.estimators.in_loop == "fused"
    run(s, tmp_path / "run")
    for stage in (fc.predict, fc.cable_readings, fc.update_cables, fc.update_tag, fc.inject):
        assert len(stage.signatures) == 1, stage.signatures
