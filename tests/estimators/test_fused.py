"""Est. 7, ``fused``: consistency against the twin's ground truth, and its cases.

The Monte Carlo: 50 runs of the paper's open-loop path (its first 4 s, camera off: the cables
and the commanded twist only), each on a robot built to the nominal model whose per-robot
realism draws (drum radii, tension-sensor bias and gain) and per-run noise (tension readings,
encoder quantisation, homing offset) come from its own seeds, with the ``acrobot`` profile.
Each estimate's error against the twin's ground truth, normalised by the filter's own covariance
(NEES), averaged over the runs, must lie within the 95 % χ²(6N)/N bounds (Bar-Shalom §5.4).
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import reference_fused as reference
from conftest import paper_pose

from cdpr_twin.estimators.base import TAG_LOST
from cdpr_twin.estimators.fused import CABLE_OUTLIER, PREDICTED, SLACK_CABLES, TAG_OUTLIER
from cdpr_twin.math import se3
from cdpr_twin.plugins import make_estimator
from cdpr_twin.recording.timeseries import load_timeseries
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.study.nees import monte_carlo
from cdpr_twin.types import Command, Measurement, TagDetection

ROOT = Path(__file__).resolve().parents[2]
RUNS = 50


def _open_loop(duration: float, camera: bool, nominal_geometry: bool):
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    options = dict(s.estimators.options)
    if nominal_geometry:  # the robot is built to the model: the filter is told so
        options["fused"] = replace(
            options["fused"],
            exit_point_std=0.0,
            anchor_point_std=0.0,
            camera_position_std=0.0,
            camera_rotation_std=0.0,
        )
    s = replace(s, estimators=replace(s.estimators, passive=("fused",), options=options))
    return s.with_overrides(duration=duration, camera=camera)


def test_nees_over_50_runs_lies_within_the_95_percent_chi2_bounds():
    result = monte_carlo(_open_loop(4.0, camera=False, nominal_geometry=True), "fused", RUNS)
    lo, hi = result.bounds(0.95)
    average = result.average[1:]  # t = 0 is the reset pose: the prior itself
    anees = float(average.mean())
    inside = float(np.mean((average > lo) & (average < hi)))
    print(f"ANEES {anees:.2f} within [{lo:.2f}, {hi:.2f}]; {inside:.0%} of ticks inside")
    assert lo < anees < hi
    assert inside >= 0.95
    # not consistent by being vague: the errors are millimetres and so are the sigmas
    assert 2e-4 < np.sqrt(np.mean(result.errors[:, -1, :3] ** 2)) < 3e-3


def _static_measurement(twin, T, t=0.0, **changes):
    m = twin.sense()
    fields = {"time": t, "cable_lengths": m.cable_lengths, "tensions": m.tensions}
    fields.update(changes)
    return Measurement(**fields)


def test_outlier_cable_is_gated_and_slack_cables_are_left_out(twin):
    T = paper_pose("p2")
    twin.reset(T)
    est = make_estimator("fused", twin.nominal_geometry)
    est.reset(T)
    m0 = _static_measurement(twin, T)
    est.update(m0)
    zero = Command(np.zeros(8), np.zeros(6))
    bad = m0.cable_lengths.copy()
    bad[2] += 0.005  # a 5 mm encoder glitch on cable 3
    e = est.update(Measurement(0.04, bad, m0.tensions, command=zero))
    assert CABLE_OUTLIER in e.flags
    assert se3.pose_distance(e.T_base_platform, twin.T_base_platform)[0] < 20e-6
    slack = m0.tensions.copy()
    slack[[0, 5]] = 0.2
    e = est.update(Measurement(0.08, m0.cable_lengths, slack, command=zero))
    assert SLACK_CABLES in e.flags and CABLE_OUTLIER not in e.flags
    assert se3.pose_distance(e.T_base_platform, twin.T_base_platform)[0] < 20e-6


def test_without_usable_readings_it_predicts_and_its_covariance_grows(twin):
    T = paper_pose("p0")
    twin.reset(T)
    est = make_estimator("fused", twin.nominal_geometry)
    est.reset(T)
    m0 = _static_measurement(twin, T)
    est.update(m0)
    twist = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    traces = []
    for k in range(1, 6):  # every cable reads slack, the tag is lost: prediction only
        command, image = Command(np.zeros(8), twist), np.zeros((2, 2, 3), np.uint8)
        m = Measurement(0.04 * k, m0.cable_lengths, np.zeros(8), command=command, image=image)
        e = est.update(m)
        assert {PREDICTED, TAG_LOST, SLACK_CABLES} <= e.flags
        traces.append(np.trace(e.covariance))
    assert np.all(np.diff(traces) > 0)
    moved = T @ se3.se3_exp(twist * 0.2)  # the commanded twist, integrated (eq. 9)
    assert se3.pose_distance(e.T_base_platform, moved)[0] < 1e-12


def _detection(T_base_platform, T_platform_cam, T_base_tag):
    T_cam_tag = se3.inverse(T_base_platform @ T_platform_cam) @ T_base_tag
    return TagDetection(0, np.zeros((4, 2)), T_cam_tag, 50.0, 0.1)


def test_tag_anchors_then_corrects_and_an_outlier_detection_is_rejected(twin):
    g = twin.nominal_geometry
    T = paper_pose("p1")
    T_base_tag = T @ g.T_platform_cam @ se3.pose_from_vector([0.0, 0.0, 0.09, 180, 0, 180])
    est = make_estimator("fused", g, tag_latency=0.0)
    est.reset(T)
    slack, image = np.zeros(8), np.zeros((2, 2, 3), np.uint8)
    cmd = Command(np.zeros(8), np.zeros(6))
    est.update(
        Measurement(
            0.0, np.ones(8), slack, image=image, tag=_detection(T, g.T_platform_cam, T_base_tag)
        )
    )
    assert est.T_base_tag is not None
    blind = make_estimator("fused", g, tag_latency=0.0)  # the same, but loses the tag
    blind.reset(T)
    blind.update(
        Measurement(
            0.0, np.ones(8), slack, image=image, tag=_detection(T, g.T_platform_cam, T_base_tag)
        )
    )
    # 1 s later, the platform moved by what the process noise allows (≈ 1 mm, 0.05° per √s)
    T_moved = T @ se3.se3_exp([0.001, -0.0005, 0.0, 0.0, 0.0, 0.001])  # unknown to the filter
    e = est.update(
        Measurement(
            1.0,
            np.ones(8),
            slack,
            command=cmd,
            image=image,
            tag=_detection(T_moved, g.T_platform_cam, T_base_tag),
        )
    )
    assert not e.flags & {TAG_OUTLIER, TAG_LOST}
    before = se3.pose_distance(T, T_moved)[0]
    after = se3.pose_distance(e.T_base_platform, T_moved)[0]
    assert after < 0.2 * before
    T_far = T_moved @ se3.se3_exp([0.05, 0.0, 0.0, 0.0, 0.3, 0.0])  # 5 cm, 17°: a false detection
    e2 = est.update(
        Measurement(
            1.04,
            np.ones(8),
            slack,
            command=cmd,
            image=image,
            tag=_detection(T_far, g.T_platform_cam, T_base_tag),
        )
    )
    assert TAG_OUTLIER in e2.flags
    assert se3.pose_distance(e2.T_base_platform, e.T_base_platform)[0] < 1e-5
    predicted = blind.update(Measurement(1.0, np.ones(8), slack, command=cmd, image=image))
    assert TAG_LOST in predicted.flags
    assert np.all(np.diag(e.covariance) < np.diag(predicted.covariance))


def test_covariance_columns_and_ellipsoid_are_recorded(tmp_path):
    run(_open_loop(0.4, camera=False, nominal_geometry=False), tmp_path, record_rrd=True)
    ts = load_timeseries(tmp_path / "timeseries.csv")
    P = ts.covariance("fused")
    assert "model_simple_cov_x_x" not in ts.columns and "fused_cov_rz_rz" in ts.columns
    assert np.allclose(P, np.swapaxes(P, 1, 2)) and np.all(np.linalg.eigvalsh(P) > 0)
    assert 1e-4 < np.sqrt(P[-1, 0, 0]) < 0.02  # millimetres: homing and calibration priors
    assert (tmp_path / "recording.rrd").stat().st_size > 0


@pytest.mark.parametrize("name", ["fused"])
def test_fused_rejects_bad_options(twin, name):
    with pytest.raises(ValueError, match="pixel_std"):
        make_estimator(name, twin.nominal_geometry, pixel_std=-1.0)
    with pytest.raises(ValueError, match="hang_threshold"):
        make_estimator(name, twin.nominal_geometry, hang_threshold=2.0)  # taut_threshold 1 N


@pytest.mark.parametrize("view", ["tilted", "face_on"])
def test_calibration_jacobian_matches_opencv_pnp_with_a_miscalibrated_camera(view):
    """∂n/∂δk against OpenCV: corners projected by a true camera (K, Brown–Conrady), the pose
    solved with each calibrated parameter off by a small step, n = log(T_true⁻¹ T̂)."""
    import cv2

    from cdpr_twin.estimators import fused_models as fm

    f, size = 415.69, 0.04
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
    dist = np.array([-0.2, 0.08, 0.002, -0.002])
    rot = [0.35, -0.25, 0.1] if view == "tilted" else [0.0, 0.0, 0.05]
    T = se3.transform(cv2.Rodrigues(np.array(rot))[0], np.array([0.04, -0.03, 0.3]))
    h = size / 2
    obj = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    rvec = cv2.Rodrigues(T[:3, :3])[0]
    pix = cv2.projectPoints(obj, rvec, T[:3, 3], K, dist)[0].reshape(4, 2)
    steps = [0.5, 0.5, 0.5, 0.5, 1e-3, 1e-3, 1e-4, 1e-4]
    M = fm.tag_calibration_jacobian(T, size, f, dist)
    for j, step in enumerate(steps):
        n_fd = []
        for sign in (1.0, -1.0):
            k = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist])
            k[j] += sign * step
            K_cal = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]])
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
            r, t = cv2.solvePnPRefineLM(obj, pix, K_cal, k[4:], rvec.copy(), T[:3, 3:].copy(), crit)
            T_hat = se3.transform(cv2.Rodrigues(r)[0], t.ravel())
            n_fd.append(se3.se3_log(se3.inverse(T) @ T_hat))
        fd = (n_fd[0] - n_fd[1]) / (2 * step)
        # measured: within 0.3 % of the largest component (the difference quotient's error)
        assert np.allclose(M[:, j], fd, rtol=0.01, atol=0.01 * np.abs(fd).max()), (j, M[:, j], fd)


def test_a_nearly_singular_taut_set_does_not_blow_up_the_prediction(twin):
    """At p0, cables 2, 3, 4, 6, 7, 8 taut (the PBVS start: 1 and 5 slack) form a Jacobian of
    condition number ≈ 3·10⁴: A⁺ maps a drum's 0.5 % of a 1.6 mm step into a 13 mm std growth
    in one step (a 92 mm jump of the estimate was seen in a run). The guard propagates the twist
    alone there (0.3 mm); with the well-conditioned set 2-7 the drums' share is kept."""
    from cdpr_twin.estimators.solvers import _cable_tuples, _kernel, _pose

    g = twin.nominal.geometry
    T0 = paper_pose("p0")
    xi = np.array([0.02, -0.02, -0.03, 0.03, 0.02, 0.0])
    _, rows = _kernel(_cable_tuples(g.a_base, g.b_platform, g.pulley_radius), True, _pose(T0))
    rates = np.asarray(rows) @ xi  # l̇ = A ξ (platform frame)
    growth = {}
    for label, slack in (("singular", [0, 4]), ("sound", [0, 7]), ("still", [0, 4])):
        est = make_estimator("fused", g)
        est.reset(T0)
        before = est.P[:3, :3].copy()
        taut = np.ones(8, dtype=bool)
        taut[slack] = False
        r = np.zeros(8) if label == "still" else rates
        est.predict(xi, 0.04, r, taut)
        growth[label] = float(np.sqrt(np.linalg.eigvalsh(est.P[:3, :3] - before).max()))
    assert growth["singular"] < 1e-3  # 13 mm without the guard
    assert growth["sound"] > growth["still"] * (1 + 1e-6)  # the drums' share is there


def test_the_fast_joseph_update_is_the_product_form_with_zero_considered_gains():
    """P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ with K's considered rows zero (the dense, O(n³) form),
    against the O(n²k) update: the same matrix, and the considered block untouched."""
    rng = np.random.default_rng(7)
    for n, k, c in ((26, 8, 18), (88, 6, 18), (40, 3, 40), (12, 1, 5)):
        A = rng.normal(size=(n, n))
        P = A @ A.T + 1e-6 * np.eye(n)
        H, r = rng.normal(size=(k, n)), rng.normal(size=k)
        B = rng.normal(size=(k, k))
        R = B @ B.T + 0.1 * np.eye(k)
        dx, P_fast, nis = reference.joseph_update(P, H, R, r, c)
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        K[c:] = 0.0
        IKH = np.eye(n) - K @ H
        P_dense = IKH @ P @ IKH.T + K @ R @ K.T
        scale = np.abs(P).max()
        assert np.abs(P_fast - P_dense).max() < 1e-12 * scale
        np.testing.assert_allclose(dx, K @ r, rtol=1e-12, atol=1e-14)
        assert np.array_equal(P_fast[c:, c:], 0.5 * (P[c:, c:] + P[c:, c:].T))
        assert np.array_equal(P_fast, P_fast.T)
        assert nis == pytest.approx(r @ np.linalg.solve(S, r), rel=1e-12)


def test_a_measurement_of_another_robot_is_refused_in_one_line(twin):
    """The compiled stages read one entry per cable of the geometry: seven readings for
    eight cables are an error that names the fields, not a read past an array's end."""
    est = make_estimator("fused", twin.nominal_geometry)
    est.reset(paper_pose("p0"))
    seven = Measurement(0.04, np.ones(7), np.full(7, 20.0), Command(np.zeros(7), np.zeros(6)))
    with pytest.raises(ValueError, match=r"^fused: cable_lengths, tensions and the command's "):
        est.update(seven)


def test_a_twist_that_is_not_six_numbers_is_refused_in_one_line():
    """The compiled prediction reads six entries of the commanded twist: a command with
    another count is an error naming the field, made where the command is built."""
    for n in (3, 8):
        with pytest.raises(ValueError, match=r"^Command.twist_platform must be \(6,\)"):
            Command(np.zeros(8), np.zeros(n))


def test_integer_readings_of_a_log_give_the_same_estimate_as_floats(twin):
    """A log may hold integers: the measurement holds them as float64, so the filter computes
    on the same numbers (an integer-valued reading is the same float) and the same estimate."""
    lengths = np.round(twin.sense().cable_lengths, 0) + 1.0
    tensions = np.arange(20, 28)
    estimates = []
    for kind in (int, float):
        est = make_estimator("fused", twin.nominal_geometry)
        est.reset(paper_pose("p0"))
        m = Measurement(0.04, lengths.astype(kind), tensions.astype(kind))
        assert m.cable_lengths.dtype == m.tensions.dtype == np.float64
        estimates.append(est.update(m))
    assert np.array_equal(estimates[0].T_base_platform, estimates[1].T_base_platform)
    assert np.array_equal(estimates[0].covariance, estimates[1].covariance)


def test_a_layout_with_a_corrected_state_after_a_considered_one_is_refused():
    from cdpr_twin.estimators import fused_models as fm

    good = fm.Layout.build(8, True, True, True, True)
    assert good.consider[good.corrected :].all() and not good.consider[: good.corrected].any()
    bad = good.consider.copy()
    bad[-1] = False
    with pytest.raises(ValueError, match="last"):
        fm.Layout(**{**{f: getattr(good, f) for f in vars(good)}, "consider": bad})


@pytest.mark.parametrize(("hang_threshold", "consistent"), [(0.27, True), (1.0, False)])
def test_a_robot_hanging_on_a_weakly_taut_cable_keeps_the_filter_consistent(
    hang_threshold, consistent
):
    """Robot 4 of the paper's tolerances (camera off, p0 → p1): the platform hangs on six
    cables, one of them reading ≈ 0.6 N (two read their bias: slack). The prediction maps the
    geometry and drum errors into the motion only through the cables it takes the platform to
    hang on; counted from 1 N up it sees five, maps nothing, and its rotation error (2° of
    drift) sits at NEES ≈ 40; counted from above what a slack cable can read (0.27 N), its
    covariance holds that error: the run's mean NEES (6 dof, and rotation alone) below the
    χ² 95 % quantile, and not vague (above the 5 % one). One autocorrelated run: the means are
    a check of scale, not a χ² test (measured over run seeds 1-8: 5.8-9.1 vs 37-48)."""
    from scipy.stats import chi2

    from cdpr_twin.study.nees import run_errors

    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    options = dict(s.estimators.options)
    options["fused"] = replace(options["fused"], hang_threshold=hang_threshold)
    est = replace(s.estimators, passive=("fused",), options=options)
    s = replace(s, truth=replace(s.truth, seed=4), estimators=est)
    _, err, cov = run_errors(s.with_overrides(duration=10.0, camera=False), "fused")
    nees = np.einsum("ki,kij,kj->k", err, np.linalg.inv(cov), err)
    rot = np.einsum("ki,kij,kj->k", err[:, 3:], np.linalg.inv(cov[:, 3:, 3:]), err[:, 3:])
    assert np.degrees(np.abs(err[:, 3:]).max()) > 1.5  # the drift is there either way
    ok = nees.mean() < chi2.ppf(0.95, 6) and rot.mean() < chi2.ppf(0.95, 3)
    assert ok == consistent, (nees.mean(), rot.mean())  # measured 6.7 / 4.4 and 44 / 40
    assert nees.mean() > chi2.ppf(0.05, 6)  # overconfident or not, never vague
