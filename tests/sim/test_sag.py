"""Cables with mass in the physics (cdpr_twin/sim/sag.py): Irvine's catenary on every free span.

Truth: the massless twin (the same model, the same rest lengths): sagging cables must move the
settled platform by what is expected on ACROBOT (< 10 µm: 2.4 g/m Dyneema, ≈ 0.9 mm sag)
and measurably more on CoGiRo (0.064 kg/m steel over ≈ 10 m). The catenary element itself is
checked against a discretised MuJoCo cable in tests/math/test_catenary.py.
"""

import mujoco
import numpy as np
import pytest
from conftest import PAPER_POSES

from cdpr_twin import DEFAULT_SCENE, MODELS_DIR
from cdpr_twin.math import se3
from cdpr_twin.sim import Physics, build_model, build_robot
from cdpr_twin.sim.mjcf_from_robot import build_files
from cdpr_twin.sim.model import swivel_body
from cdpr_twin.sim.sag import SaggingPhysics


def _settled_change(scene, pose, rho, settle=1.0, hold=1.0):
    plain = Physics(build_model(scene), 40)
    heavy = SaggingPhysics(build_model(scene), 40, linear_density=rho)
    T = se3.pose_from_vector(pose)
    for p in (plain, heavy):
        p.reset(T, settle_time=settle)
        p.advance(hold, np.zeros(p.n_cables))
    np.testing.assert_array_equal(plain.rest_lengths, heavy.rest_lengths)
    assert np.abs(heavy.data.qvel).max() < 1e-3  # at rest
    return se3.pose_distance(plain.T_base_platform, heavy.T_base_platform)[0], heavy


@pytest.mark.parametrize("name", ["p0", "p1", "p2"])
def test_sag_moves_acrobots_settled_pose_by_less_than_10_um(name):
    dt, heavy = _settled_change(DEFAULT_SCENE, PAPER_POSES[name], 0.0024)
    assert 1e-7 < dt < 1e-5  # measured 0.95, 8.3, 6.2 µm at p0, p1, p2
    # the heavier cable needs more stretch to sag between the same points: it pulls harder
    assert np.all(heavy.sag_force @ np.array([0.0, 0.0, 1.0]) > -0.01)


def test_sag_on_cogiro_moves_the_settled_pose_by_a_fraction_of_a_millimetre():
    dt, _ = _settled_change(MODELS_DIR / "cogiro" / "scene.xml", [2.0, -1.5, 1.0, 0, 0, 0], 0.064)
    assert 1e-4 < dt < 2e-3  # measured 0.45 mm (tensions 160–480 N)


def test_a_description_with_sag_builds_sagging_physics(tmp_path):
    text = (MODELS_DIR / "cogiro" / "robot.toml").read_text()
    assert "\nsag = true" in text  # CoGiRo's heavy steel cables sag in the physics
    physics = build_robot(MODELS_DIR / "cogiro" / "scene.xml").physics
    assert isinstance(physics, SaggingPhysics) and physics.linear_density == 0.064
    path = tmp_path / "robot.toml"
    texture = MODELS_DIR / "acrobot" / "assets" / "tag36h11_00000.png"  # from anywhere
    text = text.replace("\nsag = true", "\nsag = false")
    path.write_text(text.replace('"../acrobot/assets/tag36h11_00000.png"', f'"{texture}"'))
    _, scene = build_files(path, tmp_path)
    physics_plain = build_robot(scene).physics
    assert type(physics_plain) is Physics


@pytest.fixture(scope="module")
def cogiro_at_rest():
    """CoGiRo (heavy cables, sensors at the pulleys) settled at p1 and held still."""
    from cdpr_twin.sim import Twin

    twin = Twin(robot="cogiro", camera=False, tension_noise_std=0.0, home_encoders=False)
    twin.reset(se3.pose_from_vector([2.0, -1.5, 1.0, 0, 0, 0]), settle_time=1.0)
    twin.advance(4.0, np.zeros(8))
    physics = twin.physics
    physics.refresh()  # the spans' forces at this very state
    assert np.abs(physics.data.qvel).max() < 1e-3  # at rest
    yield twin
    twin.close()


def _spans(physics):
    """Each span's upper end (the sheave's tangent point), its lower end B_i, its unit B → top."""
    d = physics.data
    points = d.wrap_xpos.reshape(-1, 3)
    tendons = physics._tendons
    top = np.array([points[d.ten_wrapadr[t] + d.ten_wrapnum[t] - 2] for t in tendons])
    bottom = d.site_xpos[physics._anchors]
    return top, bottom


def test_the_pulley_side_tension_exceeds_the_anchors_by_the_weight_of_the_rise(cogiro_at_rest):
    # along a hanging cable dT/dz = w / (1 + T/EA) (Irvine 1981, the elastic catenary's
    # tension–height relation): T_top − T_B = w·Δz to the relative order T/EA (< 1e-2 here)
    p = cogiro_at_rest.physics
    top, bottom = _spans(p)
    rise = top[:, 2] - bottom[:, 2]
    w = 0.064 * 9.81
    gap = p.pulley_tensions - p.tensions
    np.testing.assert_allclose(gap, w * rise, rtol=2e-2)
    assert np.all(gap > 1.0)  # measured 2.1–2.7 N (rises 3.4–4.4 m): half the 5 N noise


def test_the_pulleys_carry_the_platform_and_the_cables_weight(cogiro_at_rest):
    # vertical force balance of platform + cables: what the pulleys hold up is the platform's
    # weight and inertia (MuJoCo's mass and acceleration) plus every span's weight w·l_s
    p = cogiro_at_rest.physics
    top, bottom = _spans(p)
    unit = (top - bottom) / np.linalg.norm(top - bottom, axis=1)[:, None]
    straight = 0.0 - p.data.actuator_force[p._actuators]
    on_pulleys = -straight[:, None] * unit + p.pulley_force  # the cables pull the sheaves down
    chord = np.linalg.norm(top - bottom, axis=1)
    spans = p.rest_lengths * chord / (p.data.ten_length[p._tendons] - p._entry)
    mujoco.mj_forward(p.model, p.data)  # MuJoCo's acceleration of the (almost still) platform
    lift = float(p.model.body_subtreemass[p._platform]) * (9.81 + p.data.qacc[p._dof + 2])
    held = -on_pulleys[:, 2].sum()  # measured 941.7 N
    np.testing.assert_allclose(held, lift + 0.064 * 9.81 * spans.sum(), rtol=1e-4)


def test_the_pulley_force_lies_in_its_swivels_plane(cogiro_at_rest):
    # the swivels turn about a vertical axis; a catenary hangs in the vertical plane of its
    # chord, so the force on the sheave is in the sheave's plane: the swivel needs no other turn
    p = cogiro_at_rest.physics
    top, bottom = _spans(p)
    unit = (top - bottom) / np.linalg.norm(top - bottom, axis=1)[:, None]
    straight = 0.0 - p.data.actuator_force[p._actuators]
    force = -straight[:, None] * unit + p.pulley_force
    bodies = [
        mujoco.mj_name2id(p.model, mujoco.mjtObj.mjOBJ_BODY, swivel_body(i)) for i in range(8)
    ]
    normals = p.data.xmat[bodies].reshape(-1, 3, 3)[:, :, 1]  # the sheave's axis (its y)
    off_plane = np.abs(np.einsum("ij,ij->i", force, normals)) / np.linalg.norm(force, axis=1)
    assert off_plane.max() < 1e-3  # the swivel's refresh lags the pose by < one refresh


def test_the_tension_sensors_read_the_pulley_side_on_cogiro(cogiro_at_rest):
    twin = cogiro_at_rest
    np.testing.assert_array_equal(twin.sense().tensions, twin.physics.pulley_tensions)
    assert twin.nominal.geometry.sensors_at_pulleys


def _irvine_tension(p, i: int, ls: float) -> float:
    """The tension at B_i of the span of unstretched length ``ls`` (Irvine 1981, eqs. 2.19-2.20,
    lower end at the origin), solved with scipy's fsolve: independent of cdpr_twin.math.catenary."""
    from scipy.optimize import fsolve

    top, bottom = _spans(p)
    h, v = np.hypot(*(top[i] - bottom[i])[:2]), (top[i] - bottom[i])[2]
    w, ea = p.weight, p._es[i]

    def ends(x):
        H, V = np.exp(x[0]), x[1]  # H > 0; V: the tension's upward part at B_i
        s = ls
        xe = H * s / ea + H / w * (np.arcsinh((V + w * s) / H) - np.arcsinh(V / H))
        ze = (w * s * s / 2 + V * s) / ea + H / w * (
            np.hypot(1, (V + w * s) / H) - np.hypot(1, V / H)
        )
        return [xe - h, ze - v]

    H, V = fsolve(ends, [np.log(50.0), 0.0], xtol=1e-13)
    assert np.allclose(ends([H, V]), 0, atol=1e-9)
    return float(np.hypot(np.exp(H), V))


def test_a_heavy_cable_pulls_on_across_its_chords_length_and_ends_hold_its_weight(cogiro_at_rest):
    # Before: a span 24 µm longer than its 8.7 m chord pulled 0 N on B_1, 1e-6
    # shorter 105 N: the catenary was dropped where MuJoCo's straight cable goes slack. Truth:
    # continuity across the chord's length, and beyond it Irvine's equations solved by scipy.
    p = cogiro_at_rest.physics
    top, bottom = _spans(p)
    chord = float(np.linalg.norm(top[0] - bottom[0]))
    total = float(p.data.ten_length[p._tendons[0]]) - p._entry  # l0 = l_s · total / chord
    unit = (top[0] - bottom[0]) / chord
    pulls = {}
    for r in (1 - 1e-9, 1 + 1e-9, 1.0001, 1.001, 1.01):
        ls = r * chord
        on_b = p._span_force(0, bottom[0], ls * total / chord)
        on_b = on_b + p._es[0] * max(chord - ls, 0.0) / ls * unit  # + MuJoCo's straight pull
        pulls[r] = np.linalg.norm(on_b)
        if r > 1:  # slack in MuJoCo: the pull is the hanging span's alone (Irvine, solved apart)
            irvine = _irvine_tension(p, 0, ls)  # (measured: they agree to ~1e-10)
            assert np.linalg.norm(on_b) == pytest.approx(irvine, rel=1e-6)
    assert abs(pulls[1 + 1e-9] / pulls[1 - 1e-9] - 1) < 1e-4  # (E·S·2e-9 apart: 6e-4 N)
    assert pulls[1.0001] > pulls[1.001] > pulls[1.01] > 0.0  # a longer cable hangs slacker
    p.refresh()  # (the module's state back for the other tests)


def test_cables_with_mass_refuse_a_gravity_off_the_vertical():
    # before: the cables' weight was 9.81 N/kg straight down whatever the model's gravity
    m = build_model(MODELS_DIR / "cogiro" / "scene.xml")
    m.opt.gravity[:] = [1.0, 0.0, -9.81]
    with pytest.raises(ValueError, match="gravity along -z"):
        SaggingPhysics(m, 40, linear_density=0.064)
    m.opt.gravity[:] = [0.0, 0.0, -3.0]  # the Moon's or a test's: the weight follows it
    assert SaggingPhysics(m, 40, linear_density=0.064).weight == pytest.approx(0.064 * 3.0)


def test_a_heavy_cable_hanging_beyond_its_chord_is_slack_to_the_monitor():
    # once hanging cables report their catenary's pull, the monitor counted CoGiRo's
    # paid-out cables taut (20-45 N each) and its loss of constraint never fired. Truth:
    # MuJoCo's own cable force, 0 for a cable longer than its path
    from cdpr_twin.sim import build_robot
    from cdpr_twin.sim.monitor import FaultKind, Monitor, robot_limits

    physics = build_robot(MODELS_DIR / "cogiro" / "scene.xml").physics
    physics.reset(se3.pose_from_vector([0, 0, 2.0, 0, 0, 0]), settle_time=1.0)
    monitor = Monitor(physics, robot_limits(physics, 6000.0, 0.04))
    monitor.reset()
    physics.add_hook(monitor)
    rates = np.zeros(8)
    rates[[0, 1, 4, 5]] = 0.05  # four cables paid out: 10 cm in 2 s
    physics.advance(2.0, rates)
    straight = 0.0 - physics.data.actuator_force[physics._actuators]
    assert np.all(straight[[0, 1, 4, 5]] == 0.0)  # MuJoCo: longer than their paths
    assert np.all(physics.tensions[[0, 1, 4, 5]] > 1.0)  # they hang, and still pull
    assert physics.taut.tolist() == (straight > 0).tolist()
    assert FaultKind.SLACK in [f.kind for f in monitor.faults]
