"""Model-based estimators (Est. 3-6) against the twin's ground truth and against each other."""

import numpy as np
import pytest
from conftest import paper_pose, random_workspace_poses
from hypothesis import given, settings
from hypothesis import strategies as st

from cdpr_twin.estimators.base import FEW_TAUT_CABLES, NON_FINITE_INPUT
from cdpr_twin.estimators.model_based import solve_fast, solve_scipy
from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.math.statics import InfeasibleTensionError, tension_distribution
from cdpr_twin.plugins import make_estimator
from cdpr_twin.types import Measurement

MODELS = ["model_simple", "model_elastic", "model_pulley", "model_elastic_pulley"]
OFFSET = se3.se3_exp([0.004, -0.003, 0.002, 0.01, -0.008, 0.012])  # warm start ≈ 5 mm / 1°


def _static_poses(geom, n, seed):
    out = []
    for T in random_workspace_poses(4 * n, seed=seed):
        try:
            tension_distribution(geom, T)
        except InfeasibleTensionError:
            continue
        out.append(T)
        if len(out) == n:
            return out
    raise AssertionError("not enough feasible random poses")


def _estimate(name, twin, T_start, **options):
    est = make_estimator(name, twin.nominal_geometry, **options)
    est.reset(T_start)
    return est.update(twin.sense())


def _predicted_error(twin, name, cables):
    """Pose error the neglected effect predicts: the residual the variant's model leaves at the
    true pose, mapped through its (linearised) Jacobian on the six cables used."""
    g, T = twin.true_geometry, twin.T_base_platform
    l0, tau = twin.rest_lengths, twin.tensions
    est = make_estimator(name, g)
    model = "pulley" if est.pulley else "straight"
    residual = kin.cable_lengths(g, T, model) - est.corrected_lengths(l0, tau)
    A = kin.jacobian(g, T, "base", model)[list(cables)]
    dx = -np.linalg.solve(A, residual[list(cables)])
    return np.linalg.norm(dx[:3]), np.linalg.norm(dx[3:]), np.linalg.cond(A)


def test_matching_model_recovers_truth_and_simpler_models_are_biased_as_predicted(twin):
    poses = [paper_pose(n) for n in ("p0", "p1", "p2")]
    poses += _static_poses(twin.true_geometry, 50, seed=7)
    errors = {name: [] for name in MODELS}
    linear = 0
    for T in poses:
        twin.reset(T)
        for name in MODELS:
            e = _estimate(name, twin, T @ OFFSET)
            assert e.valid, (name, e.flags)
            dt, dr = se3.pose_distance(e.T_base_platform, twin.T_base_platform)
            errors[name].append(dt)
            if name == "model_elastic_pulley":
                assert dt < 10e-6 and dr < 1e-4
            else:
                pt, pr, cond = _predicted_error(twin, name, e.cables)
                # Linearisation holds while the six-cable Jacobian is well conditioned; near a
                # singular six-cable subset (cond ≳ 1e3 at a few random poses) second-order
                # terms amplify the bias beyond the linear prediction.
                if cond < 1000:
                    linear += 1
                    assert abs(dt - pt) < 0.05 * pt + 1e-7, (name, dt, pt)
                    assert abs(dr - pr) < 0.05 * pr + 1e-7, (name, dr, pr)
    assert linear >= 3 * 45
    mean = {k: np.mean(v) for k, v in errors.items()}
    # stretch (tens of µm) matters less than the pulley wrap (hundreds of µm) on ACROBOT
    assert mean["model_elastic_pulley"] < mean["model_pulley"]
    assert mean["model_pulley"] < min(mean["model_simple"], mean["model_elastic"])
    assert 5e-6 < mean["model_pulley"] < 1e-4
    assert 1e-4 < mean["model_simple"] < 2e-3


def test_matching_model_tracks_a_slow_trajectory(twin):
    T = paper_pose("p1")
    twin.reset(T)
    est = make_estimator("model_elastic_pulley", twin.nominal_geometry)
    est.reset(T)
    twist = np.array([0.0, 0.0, 0.005, 0.0, 0.0, 0.0])  # 5 mm/s up, in F_b
    worst_t, worst_r = 0.0, 0.0
    for _ in range(50):  # 2 s at 25 Hz
        T_now = twin.T_base_platform
        rates = kin.jacobian(twin.nominal_geometry, T_now, "base", "pulley") @ twist
        twin.advance(0.04, rates)
        e = est.update(twin.sense())
        assert e.valid
        dt, dr = se3.pose_distance(e.T_base_platform, twin.T_base_platform)
        worst_t, worst_r = max(worst_t, dt), max(worst_r, dr)
    assert twin.T_base_platform[2, 3] > T[2, 3] + 0.009  # it did move ≈ 1 cm
    assert worst_t < 10e-6 and worst_r < 1e-4


def _synthetic_cases(geom, n, seed):
    """What a static robot at T reports (encoder rest lengths, tensions), with a warm start
    1 cm / 2° away (per-axis uniform, scaled to at most that norm)."""
    rng = np.random.default_rng(seed)
    cases = []
    for T in _static_poses(geom, n, seed):
        tensions = tension_distribution(geom, T) + rng.uniform(0.0, 1.0, geom.n_cables)
        l_pulley = geom.es * kin.cable_lengths(geom, T, "pulley") / (geom.es + tensions)
        offset = se3.se3_exp(
            np.concatenate(
                [
                    rng.uniform(-1, 1, 3) * 0.01 / np.sqrt(3),
                    rng.uniform(-1, 1, 3) * np.deg2rad(2) / np.sqrt(3),
                ]
            )
        )
        cases.append((T, l_pulley, tensions, T @ offset))
    return cases


def test_fast_and_scipy_backends_agree(twin):
    geom = twin.nominal_geometry
    worst_t = worst_r = 0.0
    for _T, lengths, tensions, T0 in _synthetic_cases(geom, 110, seed=3):
        m = Measurement(0.0, lengths, tensions)
        for name in MODELS:
            fast, slow = (make_estimator(name, geom, backend=b) for b in ("fast", "scipy"))
            fast.reset(T0)
            slow.reset(T0)
            a, b = fast.update(m), slow.update(m)
            assert a.valid and b.valid and a.cables == b.cables
            dt, dr = se3.pose_distance(a.T_base_platform, b.T_base_platform)
            worst_t, worst_r = max(worst_t, dt), max(worst_r, dr)
    assert worst_t < 1e-9 and worst_r < 1e-9


@settings(max_examples=40, deadline=None)
@given(sign=st.sampled_from([-1.0, 1.0]), scale=st.floats(0.5, 2.0), seed=st.integers(0, 10**6))
def test_scipy_solution_is_invariant_to_quaternion_sign_and_norm(sign, scale, seed):
    from cdpr_twin.sim import Twin

    geom = _GEOM or Twin(camera=False).nominal_geometry
    T, _, _, T0 = _synthetic_cases(geom, 1, seed)[0]
    lengths = kin.cable_lengths(geom, T, "pulley")  # exact: the root is T itself
    cables = np.arange(6)
    args = (
        geom.a_base[cables],
        geom.b_platform[cables],
        geom.pulley_radius[cables],
        lengths[cables],
        T0,
    )
    x0 = np.concatenate([T0[:3, 3], sign * scale * se3.quat_wxyz_from_matrix(T0[:3, :3])])
    T_ref = solve_fast(*args).T
    scipy_solution = solve_scipy(*args, x0=x0)
    dt, dr = se3.pose_distance(T_ref, scipy_solution.T)
    assert scipy_solution.residual < 1e-9 and dt < 1e-9 and dr < 1e-9
    dt, dr = se3.pose_distance(T_ref, T)
    assert dt < 1e-9 and dr < 1e-9


_GEOM = None


@pytest.fixture(autouse=True, scope="module")
def _geometry(twin):
    global _GEOM
    _GEOM = twin.nominal_geometry
    yield
    _GEOM = None


@pytest.mark.parametrize("name", MODELS)
def test_slack_cable_is_excluded(twin, name):
    T = paper_pose("p0")
    twin.reset(T)
    est = make_estimator(name, twin.nominal_geometry)
    est.reset(T)
    j = int(np.argmin(twin.tensions))
    rates = np.zeros(8)
    rates[j] = 0.01
    for k in range(40):  # 5 mm out over 0.5 s, then 1.1 s still
        twin.advance(0.04, rates if k < 12 else np.zeros(8))  # 12 × 0.4 mm ≈ 5 mm
        e = est.update(twin.sense())
    assert twin.tensions[j] == 0.0
    assert j not in e.cables and e.valid
    dt, _ = se3.pose_distance(e.T_base_platform, twin.T_base_platform)
    assert dt < 1e-3


@pytest.mark.parametrize("name", MODELS)
def test_bad_inputs_are_flagged_and_the_estimate_held(twin, name):
    T = paper_pose("p1")
    twin.reset(T)
    good = twin.sense()
    est = make_estimator(name, twin.nominal_geometry)
    est.reset(T)
    first = est.update(good)
    for field, value in (("cable_lengths", np.nan), ("tensions", np.inf), ("tensions", -np.inf)):
        arr = getattr(good, field).copy()
        arr[2] = value
        bad = Measurement(**{**vars(good), field: arr})
        e = est.update(bad)
        assert not e.valid and NON_FINITE_INPUT in e.flags
        np.testing.assert_array_equal(e.T_base_platform, first.T_base_platform)
    tensions = good.tensions.copy()
    tensions[:3] = 0.0  # only five cables taut
    e = est.update(Measurement(**{**vars(good), "tensions": tensions}))
    assert not e.valid and FEW_TAUT_CABLES in e.flags
    np.testing.assert_array_equal(e.T_base_platform, first.T_base_platform)
    assert est.update(good).valid  # and it resumes


def test_unknown_estimator_and_options():
    from cdpr_twin.math.geometry import CdprGeometry

    g = CdprGeometry(np.eye(8, 3), np.eye(8, 3), 0.0, 1.0, 1.0, np.zeros(3))
    with pytest.raises(ValueError, match="choose one of control, image"):
        make_estimator("kalman", g)
    with pytest.raises(ValueError, match="backend"):
        make_estimator("model_simple", g, backend="cuda")
    with pytest.raises(ValueError, match="bad options"):
        make_estimator("control", g, gain=2)
