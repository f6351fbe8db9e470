"""The twin's cable physics against independent truths: MuJoCo's own tendon geometry and
Jacobians, the paper's pulley equations, force balance, the elastic law and stiffness."""

import mujoco
import numpy as np
import pytest
from conftest import paper_pose, random_workspace_poses

from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.sim import SimulationError, Twin


def _mujoco_pull_directions(twin):
    """Unit vectors from each B_i toward the point where its cable leaves the sheave, taken
    from MuJoCo's wrap path (independent of cdpr_twin.math.kinematics)."""
    m, d = twin.model, twin.data
    out = []
    xpos = np.asarray(d.wrap_xpos).reshape(-1, 3)
    for t in twin.physics._tendons:
        pts = xpos[d.ten_wrapadr[t] : d.ten_wrapadr[t] + d.ten_wrapnum[t]]
        assert m.tendon_num[t] == 3 and len(pts) == 4, "entry, 2 sheave tangent points, anchor"
        v = pts[-2] - pts[-1]
        out.append(v / np.linalg.norm(v))
    return np.array(out)


# ACROBOT's cable (paper §IV-A, models/acrobot/README.md): Dyneema SK78, E = 111 GPa, Ø 2 mm
ES_PAPER = 111e9 * np.pi * 0.001**2  # E·S = 348 716.78 N


def _mujoco_cable_readings(twin):
    """(L, l0, τ) of the eight cables read from MuJoCo alone, by name: L the tendon length less
    the entry segment the model states, l0 the winch actuators' activations, τ minus the tension
    sensors' readings (actuator forces)."""
    m, d = twin.model, twin.data

    def ids(kind, fmt):
        out = np.array([mujoco.mj_name2id(m, kind, fmt.format(i + 1)) for i in range(8)])
        assert np.all(out >= 0), fmt
        return out

    tendons = ids(mujoco.mjtObj.mjOBJ_TENDON, "cable{}_tendon")
    actuators = ids(mujoco.mjtObj.mjOBJ_ACTUATOR, "winch{}_actuator")
    sensors = ids(mujoco.mjtObj.mjOBJ_SENSOR, "cable{}_tension_sensor")
    numeric = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, "cable_entry_height")
    entry = m.numeric_data[m.numeric_adr[numeric]]
    # the entry segment is the straight drop from each cableN_entry site to its exit point A_N
    # (the swivel body's origin), as MuJoCo places them
    entry_sites = ids(mujoco.mjtObj.mjOBJ_SITE, "cable{}_entry")
    swivels = ids(mujoco.mjtObj.mjOBJ_BODY, "pulley{}_swivel")
    drop = np.linalg.norm(d.site_xpos[entry_sites] - d.xpos[swivels], axis=1)
    np.testing.assert_allclose(drop, entry, rtol=1e-12)
    assert np.all(m.sensor_dim[sensors] == 1)
    L = d.ten_length[tendons] - entry
    l0 = d.act[m.actuator_actadr[actuators]]
    tau = -d.sensordata[m.sensor_adr[sensors]]
    np.testing.assert_array_equal(tau, -d.actuator_force[actuators])
    return L, l0, tau


def test_pulley_length_matches_mujoco_wrap(twin):
    """eq. 15-24 == MuJoCo's wrapped tendon length less the entry segment, over 250 poses."""
    entry = twin.physics._entry
    worst, wrap_min = 0.0, np.inf
    for T in random_workspace_poses(250, seed=1):
        twin.place(T)
        mj = twin.data.ten_length[twin.physics._tendons] - entry
        paper = kin.cable_lengths(twin.true_geometry, T, "pulley")
        straight = kin.cable_lengths(twin.true_geometry, T, "straight")
        worst = max(worst, np.max(np.abs(paper - mj)))
        wrap_min = min(wrap_min, np.min(paper - straight))
    assert worst < 1e-12  # measured ≈ 4e-16 m (required: 1 µm)
    # the wrap makes the cable longer than the straight A_i-B_i segment (order r_p)
    assert 0.0 < wrap_min < twin.true_geometry.pulley_radius.max() * np.pi / 2


def test_jacobian_matches_mujoco_tendon_jacobian_and_finite_differences(twin):
    geom = twin.true_geometry
    for T in random_workspace_poses(30, seed=2):
        twin.place(T)
        J = np.array(twin.data.ten_J).reshape(twin.model.ntendon, twin.model.nv)[
            twin.physics._tendons
        ]
        # free joint: qvel = [v of the origin in F_b, ω in F_p]
        R = T[:3, :3]
        A_p = kin.jacobian(geom, T, "platform", "pulley")
        A_b = kin.jacobian(geom, T, "base", "pulley")
        scale = np.abs(A_p).max()
        np.testing.assert_allclose(A_p[:, :3] @ R.T, J[:, :3], atol=1e-7 * scale)
        np.testing.assert_allclose(A_p[:, 3:], J[:, 3:], atol=1e-7 * scale)
        np.testing.assert_allclose(A_b[:, :3], J[:, :3], atol=1e-7 * scale)
        # central finite differences of MuJoCo's own lengths under a platform-frame twist
        h = 1e-6
        fd = np.zeros((8, 6))
        for k in range(6):
            xi = np.zeros(6)
            xi[k] = h
            twin.place(T @ se3.se3_exp(xi))
            lp = twin.cable_lengths.copy()
            twin.place(T @ se3.se3_exp(-xi))
            fd[:, k] = (lp - twin.cable_lengths) / (2 * h)
        np.testing.assert_allclose(A_p, fd, atol=1e-7 * scale * 10)


@pytest.mark.parametrize("name", ["p0", "p1", "p2"])
def test_reset_is_a_static_equilibrium(twin, name):
    T = paper_pose(name)
    twin.reset(T, settle_time=0.5)
    dt, dr = se3.pose_distance(T, twin.T_base_platform)
    assert dt < 1e-4 and np.rad2deg(dr) < 0.01
    assert np.linalg.norm(twin.data.qvel) < 1e-6
    tau = twin.tensions
    assert np.all(tau >= twin.tau_min - 1e-6)
    # force balance with MuJoCo's own cable directions: Σ τ_i ũ_i + m g = 0, moments about
    # the centre of mass likewise
    u = _mujoco_pull_directions(twin)
    b = twin.data.site_xpos[twin.physics._anchors]
    com = twin.data.xipos[twin.physics._platform]
    mass = twin.model.body_mass[twin.physics._platform]
    f = (tau[:, None] * u).sum(axis=0) + mass * twin.model.opt.gravity
    mom = np.cross(b - com, tau[:, None] * u).sum(axis=0)
    assert np.linalg.norm(f) < 1e-3
    assert np.linalg.norm(mom) < 1e-3
    # the elastic law with the paper's E·S on MuJoCo's tendon lengths and tension sensors
    # (measured: relative error ≤ 4.4e-8, the model file's rounding of E·S to 348 716.8 N; the
    # damping term c L̇ is below round-off at rest)
    L, l0, tau_sensor = _mujoco_cable_readings(twin)
    assert np.all(L > l0)
    np.testing.assert_allclose(tau_sensor, ES_PAPER / l0 * (L - l0), rtol=1e-6)


def test_tension_is_the_paper_cable_law_on_mujoco_lengths_taut_or_slack(twin):
    """Hold the winches of a p0 equilibrium (stretches 13-22 µm) and place the platform up to
    20 µm and 2e-4 rad away: each cable stretches or slackens to MuJoCo's tendon length, and
    its tension sensor must read (E·S/l0)·max(0, L − l0) with the paper's E·S (the platform is
    at rest: no damping)."""
    T = paper_pose("p0")
    twin.reset(T, settle_time=0.2)
    rng = np.random.default_rng(4)
    n_slack = n_taut = 0
    for _ in range(20):
        xi = np.concatenate([rng.uniform(-2e-5, 2e-5, 3), rng.uniform(-2e-4, 2e-4, 3)])
        twin.place(T @ se3.se3_exp(xi))
        L, l0, tau = _mujoco_cable_readings(twin)
        stretch = L - l0
        taut = stretch > 0
        n_taut, n_slack = n_taut + taut.sum(), n_slack + (~taut).sum()
        # measured: relative error ≤ 4.5e-8 (E·S rounded in the model file)
        np.testing.assert_allclose(tau[taut], ES_PAPER / l0[taut] * stretch[taut], rtol=1e-6)
        assert np.all(tau[~taut] == 0.0)  # a slack cable never pushes
    assert n_taut > 100 and n_slack > 20  # measured 130 and 30: both branches exercised


def test_stiffness_matches_analytic(twin):
    """A 2 N downward load moves the platform by K⁻¹ δw, K = Aᵀ diag(E·S/l0) A."""
    T = paper_pose("p0")
    twin.reset(T, settle_time=0.2)
    K = kin.stiffness_matrix(twin.true_geometry, T, twin.rest_lengths, "pulley")
    dw = np.array([0.0, 0.0, -2.0, 0.0, 0.0, 0.0])
    predicted = np.linalg.solve(K, dw)
    twin.data.xfrc_applied[twin.physics._platform] = dw
    try:
        twin.advance(1.0, np.zeros(8))
    finally:
        twin.data.xfrc_applied[twin.physics._platform] = 0.0
    T1 = twin.T_base_platform
    moved = np.concatenate([T1[:3, 3] - T[:3, 3], se3.so3_log(T1[:3, :3] @ T[:3, :3].T)])
    assert np.linalg.norm(moved[:3] - predicted[:3]) < 0.05 * np.linalg.norm(predicted[:3])
    assert np.linalg.norm(moved[3:] - predicted[3:]) < 0.05 * np.linalg.norm(predicted[3:]) + 1e-9
    assert 1e-6 < np.linalg.norm(predicted[:3]) < 1e-3  # sanity: a stiff but finite response


def test_paying_out_a_cable_slackens_it_and_reeling_in_restores_it(twin):
    T = paper_pose("p0")
    twin.reset(T, settle_time=0.2)
    tau0 = twin.tensions.copy()
    j = int(np.argmin(tau0))
    rates = np.zeros(8)
    rates[j] = 0.01
    twin.advance(0.5, rates)  # 5 mm out
    twin.advance(1.0, np.zeros(8))
    tau = twin.tensions
    assert tau[j] == 0.0  # exactly: a cable never pushes
    assert twin.cable_lengths[j] < twin.rest_lengths[j]  # geometrically slack
    assert np.sum(tau > 0.5) >= 6  # the others hold the platform
    dt, _ = se3.pose_distance(T, twin.T_base_platform)
    assert dt < 2e-3 and np.linalg.norm(twin.data.qvel) < 1e-4  # still up, at rest
    twin.advance(0.5, -rates)
    twin.advance(1.0, np.zeros(8))
    np.testing.assert_allclose(twin.tensions, tau0, atol=1e-3)
    dt, dr = se3.pose_distance(T, twin.T_base_platform)
    assert dt < 1e-6 and dr < 1e-5


def test_all_cables_slack_platform_rests_on_floor(twin):
    """Documented safe behaviour: with every cable paid out, the platform lands on the floor."""
    twin.reset(paper_pose("p1"), settle_time=0.1)
    twin.advance(1.0, np.full(8, 0.2))
    twin.advance(1.0, np.zeros(8))
    assert np.all(twin.tensions == 0.0)
    z_floor = twin.model.geom_pos[twin.model.geom("floor").id][2]
    half_height = twin.model.geom_size[twin.model.geom("platform_box").id][2]
    assert abs(twin.T_base_platform[2, 3] - half_height - z_floor) < 2e-3


def test_model_files_step_without_warnings():
    from cdpr_twin import MODELS_DIR
    from cdpr_twin.sim import Twin

    for path in sorted((MODELS_DIR / "acrobot").glob("*.xml")):
        with Twin(model_path=path, camera=False, tension_noise_std=0.0) as t:
            t.reset(paper_pose("p1"))
            A = kin.jacobian(t.nominal_geometry, paper_pose("p1"), "base", "pulley")
            t.advance(1.0, A @ [0.0, 0.0, 0.01, 0.0, 0.0, 0.0])
            t.advance(1.0, np.zeros(8))
            assert all(w.number == 0 for w in t.data.warning), path.name
            assert np.all(np.isfinite(t.data.qpos))


def test_a_closed_twin_neither_steps_nor_senses():
    twin = Twin(camera=False, tension_noise_std=0.0)
    twin.reset(paper_pose("p1"))
    twin.close()
    for act in (
        lambda: twin.advance(0.04, np.zeros(8)),
        twin.sense,
        lambda: twin.reset(paper_pose("p1")),
    ):
        with pytest.raises(SimulationError, match="closed"):
            act()
