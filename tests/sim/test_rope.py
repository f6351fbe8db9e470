"""Cables as ropes and pulleys as built (cdpr_twin/sim/rope.py) against closed forms.

Each test checks one effect against an independent truth: Hooke's law on MuJoCo's own tendon
length, the standard linear solid's creep and loss compliance, the Coulomb sheave's tension
ratio and dead band, and the paper's pulley model in each tilted swivel's frame.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.optimize import brentq

from cdpr_twin.math.kinematics import anchor_points_base, cable_lengths, pulley_lengths
from cdpr_twin.math.se3 import pose_from_vector
from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import CableRealism, PulleyRealism, profile
from cdpr_twin.sim import ModelError, build_robot
from cdpr_twin.sim.rope import relax_dashpots, sls_tension

T_P0 = pose_from_vector(np.array([0.112, -0.032, 0.301, math.radians(-12), math.radians(-10), 0]))
ES = 348716.8  # ACROBOT's E·S [N] (robot.toml)


def _robot(cable=None, pulley=None, seed=0):
    from cdpr_twin.robot.deviations import DeviationSpec

    return build_robot("acrobot", DeviationSpec(seed=seed), cable=cable, pulley=pulley).physics


def test_ideal_and_acrobot_profiles_leave_the_paper_cable():
    for name in ("ideal", "acrobot"):
        r = profile(name)
        assert r.cable == CableRealism() and r.pulley == PulleyRealism()
        assert type(_robot(r.cable, r.pulley)).__name__ == "Physics"


def test_rope_stiffness_and_drum_segment_follow_hookes_law_on_mujocos_length():
    # τ = ρ_i·E·S·(L + l_d − (l0 + l_d))/(l0 + l_d): the whole cable from drum to B_i stretches
    cable = CableRealism(rope_stiffness_ratio=0.6, rope_stiffness_std=0.05, drum_segment=1.2)
    p = _robot(cable, seed=4)
    ratios = p.rope_ratio
    assert np.all(np.abs(ratios / 0.6 - 1) < 5 * 0.05) and ratios.std() > 0  # per cable
    p.reset(T_P0)
    l0 = p.rest_lengths
    length = p.cable_lengths  # MuJoCo's wrapped tendon, less the entry segment
    expected = ratios * ES * (length - l0) / (l0 + 1.2)
    # the settled platform is at rest: the damping term (η·k·L̇) is below 1e-9 N
    np.testing.assert_allclose(p.tensions, expected, rtol=0, atol=1e-6)


def test_drum_segment_stretches_by_tau_l_over_es():
    # the same platform pose and tensions with a 1.2 m drum segment need the winches to pay
    # out τ·l/(E·S) less: the segment's stretch. Without it the tensions would be off by
    # k·τ·l/(E·S) ≈ 0.4 N.
    short, long_ = _robot(CableRealism()), _robot(CableRealism(drum_segment=1.2))
    short.reset(T_P0)
    tau = short.tensions
    long_.reset(T_P0)
    long_.data.act[long_._actuators] = short.rest_lengths - tau * 1.2 / ES
    long_.place(T_P0)
    long_.step(200)  # 0.1 s: it stays where it is, pulling as the short-cable robot does
    # ε² l_d (5e-10 m) and the settle's residue bound the difference: ≪ 1e-3 N
    np.testing.assert_allclose(long_.tensions, tau, rtol=0, atol=1e-3)
    assert np.linalg.norm(long_.T_base_platform[:3, 3] - T_P0[:3, 3]) < 1e-8


def _force_driven(tau_of_t, steps, h, es0, r, t_c):
    """Strains of one SLS cable driven by a tension τ(t) [N] (solving τ = E₀ε − E_m ε_d)."""
    es_m, decay = es0 * (1 - r), math.exp(-h / (r * t_c))
    eps_d, eps = np.zeros(1), np.zeros(1)
    out = np.empty(steps)
    for k in range(steps):
        eps[0] = (tau_of_t(k * h) + es_m * eps_d[0]) / es0
        assert sls_tension(eps, eps_d, es0, es_m)[0] == pytest.approx(tau_of_t(k * h))
        out[k] = eps[0]
        relax_dashpots(eps_d, eps, decay)
    return out


def test_creep_under_a_tension_step_follows_the_analytic_response():
    es0, r, t_c, h, tau0 = 2e5, 0.6, 1.0, 5e-4, 10.0
    eps = _force_driven(lambda t: tau0, 6000, h, es0, r, t_c)
    t = np.arange(6000) * h
    j0, j_inf = 1 / es0, 1 / (r * es0)
    analytic = tau0 * j_inf - tau0 * (j_inf - j0) * np.exp(-t / t_c)
    # the dashpot sees ε held over each step: a lag of at most one step on the creep curve,
    # h·max|dε/dt| = h·τ0(J∞ − J0)/t_c
    np.testing.assert_allclose(eps, analytic, rtol=0, atol=h * tau0 * (j_inf - j0) / t_c)
    assert eps[-1] - eps[0] > 0.9 * tau0 * (j_inf - j0)  # it did creep (≈ 95 % of ΔJ·τ0)


def test_hysteresis_loop_energy_under_sinusoidal_load_equals_the_loss_compliance():
    es0, r, t_c, h = 2e5, 0.6, 1.0, 5e-4
    omega, mean, amp = 1.0 / t_c, 10.0, 4.0
    period = round(2 * math.pi / omega / h)
    cycles = 8  # the transient decays as exp(−t/t_c): e^(−44) after 7 cycles

    def tau(t):
        return mean + amp * math.sin(omega * t)

    eps = _force_driven(tau, cycles * period + 1, h, es0, r, t_c)
    last = slice((cycles - 1) * period, cycles * period + 1)
    force = np.array([tau(k * h) for k in range(last.start, last.stop)])
    energy = np.trapezoid(force, eps[last])  # ∮ τ dε (per unit length of cable: J/m)
    d_j = 1 / (r * es0) - 1 / es0
    loss = d_j * omega * t_c / (1 + (omega * t_c) ** 2)  # J'' of the SLS
    # closed form πτ_a²J''; the one-step lag shifts the phase by ωh (5e-4 rad), the
    # trapezoid errs by O((ωh)²): 1e-3 bounds both
    assert energy == pytest.approx(math.pi * amp**2 * loss, rel=1e-3)


def test_viscoelastic_robot_rests_where_it_was_reset_and_sensors_read_the_platform_side():
    cable = CableRealism(
        rope_stiffness_ratio=0.6, relaxed_ratio=0.6, creep_time=2.0, strain_damping=True
    )
    p = _robot(cable)
    p.reset(T_P0)
    start = p.tensions.copy()
    p.step(1000)  # 0.5 s: relaxed at its tensions, nothing creeps
    assert np.linalg.norm(p.T_base_platform[:3, 3] - T_P0[:3, 3]) < 1e-8
    np.testing.assert_allclose(p.sensed_tensions, start, rtol=0, atol=1e-5)


def test_held_robot_relaxes_its_tensions_as_the_standard_linear_solid():
    # the platform held at its pose and the winches idle: each cable's strain is constant, and
    # a rope loaded at once relaxes as τ(t) = E∞ε + E_m·ε·e^(−t/t_σ), t_σ = r·t_c, which the
    # tension sensors read from MuJoCo's force
    r, t_c = 0.6, 0.5
    cable = CableRealism(relaxed_ratio=r, creep_time=t_c, strain_damping=True)
    p = _robot(cable)
    p.reset(T_P0)
    p.eps_d[:] = 0.0  # the dashpots unstretched: the rope has just been loaded
    eps = p.cable_lengths / p.rest_lengths - 1.0
    steps = 600
    for _ in range(steps):
        p.step(1)
        p.place(T_P0)  # (zero velocities: no damping force either)
    t = steps * p.timestep
    es0 = ES * np.ones(8)
    expected = es0 * r * eps + es0 * (1 - r) * eps * math.exp(-t / (r * t_c))
    # the dashpot's update is exact for a strain held constant; a step's motion before each
    # hold strains the cable by ~1e-12: round-off of metre lengths
    np.testing.assert_allclose(p.sensed_tensions, expected, rtol=1e-6)
    # it did relax, from E₀ε toward E∞ε (at t = t_σ: 0.75·E₀ε)
    assert np.all(p.sensed_tensions < 0.8 * es0 * eps)


def test_sheave_friction_gives_the_tension_ratio_and_dead_band_on_reversal():
    eta, lw, rate = 0.95, 1.2, 2e-5
    cable = CableRealism(drum_segment=lw, strain_damping=True)
    p = _robot(cable, PulleyRealism(sheave_efficiency=eta))
    p.reset(T_P0)
    rates = np.zeros(8)
    rates[0] = -rate  # reel cable 1 in: the winch side pulls the cable over the sheave
    p.advance(0.2, rates)
    k = ES / p.rest_lengths[0]
    # the platform side reads MuJoCo's force, a step behind the sheave and with its
    # damping: k·(rate·h + η·|L̇|) ≲ 4e-3 N, against a difference of (1/η − 1)·τ ≈ 0.26 N
    lag = 2 * k * (rate * p.timestep + 5e-4 * abs(p.data.ten_velocity[p._tendons][0]))
    tau_p = p.tensions[0]
    assert p.pulley_tensions[0] == pytest.approx(tau_p / eta, abs=lag / eta)
    # reversal: the cable sticks on the sheave (the platform side keeps its tension) until
    # the drum segment has gone from τ_p/η to η·τ_p: the winch pays out the segment's
    # stretch difference, Δτ·l_d/E·S (≈ 2 µm)
    u_stuck, before = p.u_p[0], p.pulley_tensions[0]
    rates[0] = rate
    travel, h = 0.0, p.timestep
    while p.u_p[0] == u_stuck:
        p.advance(h, rates)
        travel += rate * h
        assert travel < 1e-4, "the cable never slid back"
    after = p.pulley_tensions[0]
    assert after == pytest.approx(eta * p.tensions[0], abs=lag)
    # (the platform still swings a little while stuck: τ_p drifts by ≲ 1 %)
    assert before - after == pytest.approx((1 / eta - eta) * tau_p, rel=0.02)
    # within one step of travel (1e-8 m of 1.7e-6 m)
    assert travel == pytest.approx((before - after) * lw / ES, abs=rate * h)
    p.advance(0.2, rates)  # paying out: the platform side pulls the cable over the sheave
    assert p.pulley_tensions[0] == pytest.approx(eta * p.tensions[0], abs=lag)


def test_tilted_swivels_and_cable_diameter_match_mujocos_wrapped_tendon():
    d = 0.002
    pulley = PulleyRealism(wrap_diameter=d, swivel_tilt_std=math.radians(2.0))
    p = _robot(pulley=pulley, seed=1)
    flat = _robot(pulley=PulleyRealism(wrap_diameter=d), seed=1)
    p.place(T_P0)
    flat.place(T_P0)
    # the paper's pulley model in each swivel's tilted frame: A_i at the origin, the axis
    # z, the wrap radius r_p + d/2 (independent of MuJoCo's wrap)
    b = anchor_points_base(p.geometry, T_P0)
    local = np.einsum("nji,nj->ni", p._tilt_rot, b - p.geometry.a_base)
    r = np.full(8, 0.0045 + d / 2)
    expected = pulley_lengths(np.zeros((8, 3)), r, local)
    assert np.all(p.geometry.pulley_radius == r)
    np.testing.assert_allclose(p.cable_lengths, expected, rtol=0, atol=1e-12)
    # a 2° tilt moves the lengths by r·(wrap-angle change) + the chord's: tenths of a mm
    change = np.abs(p.cable_lengths - flat.cable_lengths)
    assert change.max() > 1e-5


def _belt(start, centre, r, end):
    """Length of a cable from ``start`` around a circle counter-clockwise to ``end`` (2D).

    Each straight part meets the circle at the tangent point where it runs along the
    counter-clockwise direction (−sin θ, cos θ): the cable comes down the swivel axis, under
    the sheave and out to B_i.
    """

    def tangent(p, arriving):
        d = p - centre
        base, spread = math.atan2(d[1], d[0]), math.acos(r / np.linalg.norm(d))
        for theta in (base + spread, base - spread):
            t = centre + r * np.array([math.cos(theta), math.sin(theta)])
            run = (t - p) if arriving else (p - t)
            if np.dot(run, [-math.sin(theta), math.cos(theta)]) > 0:
                return theta, t
        raise AssertionError("no tangent")

    a, ta = tangent(start, True)
    b, tb = tangent(end, False)
    arc = r * ((b - a) % (2 * math.pi))
    return np.linalg.norm(ta - start) + arc + np.linalg.norm(end - tb)


def test_offset_sheaves_on_tilted_swivels_match_mujocos_wrapped_tendon():
    # each cable in its swivel's plane: the entry point on the (tilted) axis h above A_i, the
    # sheave's centre r + δx out and δz up, B_i at its distance from the axis and height
    pulley = PulleyRealism(
        wrap_diameter=0.002, swivel_tilt_std=math.radians(2.0), sheave_offset_std=0.001
    )
    p = _robot(pulley=pulley, seed=2)
    p.place(T_P0)
    b = anchor_points_base(p.geometry, T_P0)
    local = np.einsum("nji,nj->ni", p._tilt_rot, b - p.geometry.a_base)
    r, h = 0.0045 + 0.001, 0.03
    for i in range(8):
        dx, dz = p.pulley_draws[i, 2:]
        end = np.array([np.hypot(*local[i, :2]), local[i, 2]])
        expected = _belt(np.array([0.0, h]), np.array([r + dx, dz]), r, end)
        tendon = p.data.ten_length[p._tendons][i]
        # MuJoCo's wrap and this construction agree to round-off of metre-sized lengths
        assert tendon == pytest.approx(expected, abs=1e-12)
    # the offsets (1 mm here) are drawn: leaving them out of the construction fails
    assert np.abs(p.pulley_draws[:, 2:]).max() > 1e-4


def test_bad_rope_and_pulley_fields_get_one_line_errors():
    with pytest.raises(ModelError, match="drum_segment > 0"):
        _robot(pulley=PulleyRealism(sheave_efficiency=0.9))
    with pytest.raises(ModelError, match="strain_damping = true"):
        _robot(CableRealism(drum_segment=1.0), PulleyRealism(sheave_efficiency=0.9))
    with pytest.raises(OptionError, match="strain_damping"):
        CableRealism(relaxed_ratio=0.5, creep_time=10.0)
    for cls, field, value in (
        (PulleyRealism, "sheave_efficiency", 1.5),
        (CableRealism, "relaxed_ratio", 2.0),
        (CableRealism, "rope_stiffness_ratio", 1.2),
        (CableRealism, "rope_stiffness_std", 0.5),
        (PulleyRealism, "swivel_friction", 0.2),
    ):
        with pytest.raises(OptionError, match=field) as err:
            cls(**{field: value})
        assert "\n" not in str(err.value)


def _groove_length(i, p, xyz, h=0.03):
    """The cable from the entry (h up the axis) in the groove of swivel i, out to B at xyz.

    xyz is B in the swivel's frame (x in the sheave's plane, z up the axis): the cable wraps
    the sheave as the belt to B's projection (x, z) on the plane, and its free span, a
    tangent of length √(|(x, z) − c|² − r²), takes B's offset y from the plane.
    """
    r = p._wrap_radius[i]
    c = np.array([r + p.pulley_draws[i, 2], p.pulley_draws[i, 3]])
    end = np.array([xyz[0], xyz[2]])
    span = math.sqrt(np.sum((end - c) ** 2) - r * r)
    return _belt(np.array([0.0, h]), c, r, end) - span + math.hypot(span, xyz[1])


def _static_lag(i, p, rho, z, friction_arm, e=1e-6):
    """The lag α* where the cable's moment meets the bearing's friction, by virtual work.

    The moment per newton of tension is ∂L/∂α of the groove's length (B turned by α about
    the axis), the bearing's load per newton |û + ẑ| with û = ∂L/∂B (central differences,
    truncation O(e²) ≈ 1e-12 relative).
    """

    def at(a):
        return np.array([rho * math.cos(a), rho * math.sin(a), z])

    def balance(a):
        moment = (_groove_length(i, p, at(a + e)) - _groove_length(i, p, at(a - e))) / (2 * e)
        steps = e * np.eye(3)
        u = [_groove_length(i, p, at(a) + s) - _groove_length(i, p, at(a) - s) for s in steps]
        return moment - friction_arm * np.linalg.norm(np.array(u) / (2 * e) + [0, 0, 1])

    return brentq(balance, 1e-4, 0.5, xtol=1e-14)


def _swivel_frame(p, T):
    b = anchor_points_base(p.geometry, T)
    local = np.einsum("nji,nj->ni", p._tilt_rot, b - p.geometry.a_base)
    return np.arctan2(local[:, 1], local[:, 0]), np.hypot(local[:, 0], local[:, 1]), local[:, 2]


def test_swivel_lags_where_the_cables_moment_meets_its_bearings_friction():
    mu, bore = 0.01, 0.008
    pulley = PulleyRealism(
        wrap_diameter=0.002,
        swivel_tilt_std=math.radians(2.0),
        sheave_offset_std=0.0002,
        swivel_friction=mu,
        swivel_bore=bore,
    )
    p = _robot(pulley=pulley, seed=2)
    p.reset(T_P0)
    p.place(p.T_base_platform)  # (at rest, each swivel aligned with its B_i)
    psi0 = _swivel_frame(p, p.T_base_platform)[0]
    T1 = T_P0.copy()
    T1[0, 3] += 0.03
    # 3 cm along x in 0.5 s: each azimuth ψ moves one way by up to 0.05 rad
    rates = (
        cable_lengths(p.geometry, T1, "pulley") - cable_lengths(p.geometry, T_P0, "pulley")
    ) / 0.5
    p.advance(0.5, rates)
    # the law at the last pose (mj_step leaves the sites one step behind qpos), where the
    # platform still moves the same way
    mujoco.mj_forward(p.model, p.data)
    p.refresh()
    psi, rho, z = _swivel_frame(p, p.T_base_platform)
    turned = psi - psi0
    slid = 0
    for i in range(8):
        a_star = _static_lag(i, p, rho[i], z[i], mu * bore / 2)
        if abs(turned[i]) < a_star:
            # within the friction cone all along: the swivel never moved
            assert p.swivel_lag[i] == pytest.approx(turned[i], abs=1e-9)
            continue
        slid += 1
        # the cable leaves the groove where its projection is tangent, which is not where
        # the groove's length is stationary: the exit's moment and the virtual work differ
        # by cos θ(1 + cos θ)·α²/2 ≤ α² relative
        assert p.swivel_lag[i] == pytest.approx(math.copysign(a_star, turned[i]), rel=a_star**2)
    assert slid >= 2 and slid <= 6  # both cases seen
    # the winches stop (the platform overshoots a little), then reverse by less than 2α*:
    # every swivel sticks where the stop left it, its lag follows ψ back
    p.advance(0.05, np.zeros(8))
    mujoco.mj_forward(p.model, p.data)
    p.refresh()
    psi = _swivel_frame(p, p.T_base_platform)[0]
    yaw, lag = p._swivel_yaw.copy(), p.swivel_lag.copy()
    p.advance(0.125, -rates)
    mujoco.mj_forward(p.model, p.data)
    p.refresh()
    psi_back = _swivel_frame(p, p.T_base_platform)[0]
    assert np.abs(psi_back - psi).max() > 0.005
    # (a swivel left on the cone's face may re-slip by round-off of ψ − φ: 1e-11 rad)
    np.testing.assert_allclose(p._swivel_yaw, yaw, rtol=0, atol=1e-9)
    np.testing.assert_allclose(p.swivel_lag - lag, psi_back - psi, rtol=0, atol=1e-9)


def test_lagging_swivel_lengthens_its_cable_in_the_groove_not_as_mujocos_helix():
    p = _robot(pulley=PulleyRealism(wrap_diameter=0.002, swivel_friction=0.05), seed=3)
    p.reset(T_P0)
    T = p.T_base_platform
    p.place(T)
    aligned = p.data.ten_length[p._tendons].copy()
    psi, rho, z = _swivel_frame(p, T)
    lag = np.linspace(-0.03, 0.03, 8)  # within the friction cone (α* ≥ 0.1 rad): held
    p._swivel_yaw = psi - lag
    p.refresh()
    mujoco.mj_forward(p.model, p.data)
    np.testing.assert_allclose(p.swivel_lag, lag, rtol=0, atol=1e-12)
    groove = np.array(
        [
            _groove_length(i, p, [rho[i] * math.cos(lag[i]), rho[i] * math.sin(lag[i]), z[i]])
            - _groove_length(i, p, [rho[i], 0.0, z[i]])
            for i in range(8)
        ]
    )
    assert np.all(groove[lag != 0] > 0)  # a lagging swivel lengthens its cable
    # metre-sized lengths differenced: round-off 1e-15 m
    np.testing.assert_allclose(p.groove_stretch, groove, rtol=0, atol=1e-13)
    np.testing.assert_allclose(p.cable_lengths, aligned - 0.03 + groove, rtol=0, atol=1e-15)
    # Hooke's law on that length (at rest, no damping force): ≈ 0.1 N more at 0.03 rad
    l0 = p.rest_lengths
    np.testing.assert_allclose(p.tensions, ES * (p.cable_lengths - l0) / l0, rtol=0, atol=1e-8)
    # MuJoCo's wrap of a turned sheave is a helix over the whole tendon, √(D² + y²) with D
    # the belt to B's projection: shorter than the aligned cable where the groove is longer
    for i in range(8):
        half = 0.5 * (psi[i] - lag[i])
        p.data.mocap_quat[p._mocap][i] = [math.cos(half), 0.0, 0.0, math.sin(half)]
    mujoco.mj_kinematics(p.model, p.data)
    mujoco.mj_tendon(p.model, p.data)
    r = p._wrap_radius[0]
    for i in range(8):
        end = np.array([rho[i] * math.cos(lag[i]), z[i]])
        belt = _belt(np.array([0.0, 0.03]), np.array([r, 0.0]), r, end)
        helix = math.hypot(belt, rho[i] * math.sin(lag[i]))
        assert p.data.ten_length[p._tendons][i] == pytest.approx(helix, abs=1e-12)
        if lag[i] != 0:
            assert helix < aligned[i]


def test_lagging_swivels_stretch_enters_a_viscoelastic_ropes_force():
    # the stepwise update (creep): τ = E₀ε − E_m·ε_d with ε = (L + ΔL)/l0 − 1, L MuJoCo's
    # aligned tendon less its entry segment, ΔL the groove's stretch
    cable = CableRealism(relaxed_ratio=0.6, creep_time=2.0, strain_damping=True)
    p = _robot(cable, PulleyRealism(wrap_diameter=0.002, swivel_friction=0.05), seed=3)
    p.reset(T_P0)
    p.place(p.T_base_platform)
    psi = _swivel_frame(p, p.T_base_platform)[0]
    p._swivel_yaw = psi - np.linspace(-0.03, 0.03, 8)
    p.refresh()
    mujoco.mj_forward(p.model, p.data)
    assert np.abs(p.groove_stretch).max() > 1e-7  # 0.1 N on these cables
    length = p.data.ten_length[p._tendons] - 0.03 + p.groove_stretch
    eps = length / p.rest_lengths - 1.0
    expected = ES * eps - 0.4 * ES * p.eps_d[0]
    # the force linearised about the present length is exact there (round-off: 1e-10 N)
    np.testing.assert_allclose(p.tensions, expected, rtol=0, atol=1e-8)
