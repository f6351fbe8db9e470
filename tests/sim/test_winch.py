"""Winch servos and encoders against analytic truth.

The velocity loop ṙ = clip((u − r)/τ, ±a), τ = 1/(2π f), is checked through the physics
(``build_robot(winch=…)`` and ``advance``) against the textbook closed forms of a first-order
system (step from rest with a slew-limited start; zero-order-hold ramp) and against an RK4
integration of the ODE written here; the encoders against the drum's geometry: a reading moves by
L·r/r' when the true radius r' pays out L, in counts of 2π·r/N.
"""

import math

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin import MODELS_DIR
from cdpr_twin.math import kinematics as kin
from cdpr_twin.robot.description import load_robot
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.robot.realism import Realism, WinchRealism, profile, robot_rng
from cdpr_twin.sim import Sensors, build_robot
from cdpr_twin.sim.winch import draw_drum_radii

ACROBOT_TOML = MODELS_DIR / "acrobot" / "robot.toml"

CHUNK = 0.005  # align_every (10) × timestep (0.5 ms): one physics chunk [s]
F_HZ, ACCEL = 10.0, 0.2  # bandwidth [Hz], acceleration limit [m/s²]
TAU = 1.0 / (2.0 * math.pi * F_HZ)
# a platform twist whose cable rates mix large (slew-limited, |u| > a·τ ≈ 3.2 mm/s) and small
TWIST = np.array([0.015, 0.0075, 0.0, 0.03, 0.0, 0.15])


def _robot(winch, seed=0):
    built = build_robot(deviations=DeviationSpec(seed=seed), winch=winch)
    physics, nominal = built.physics, built.nominal
    physics.reset(paper_pose("p1"))
    rates = kin.jacobian(nominal.geometry, paper_pose("p1"), "base", "pulley") @ TWIST
    return physics, nominal, rates


def _step_from_rest(u, t, tau, a):
    """Rate and paid-out length t seconds after the command steps from 0 to u (textbook).

    While the error |u − r| exceeds a·τ the loop saturates and the rate ramps at a; from
    t1 = (|u| − a·τ)/a on it is a first-order decay of the error a·τ with time constant τ.
    """
    s, big = np.sign(u), np.abs(u)
    if math.isfinite(a):
        t1 = np.maximum(big - a * tau, 0.0) / a
        ramp_r, ramp_l = a * np.minimum(t, t1), 0.5 * a * np.minimum(t, t1) ** 2
    else:
        t1, ramp_r, ramp_l = np.zeros_like(u), np.zeros_like(u), np.zeros_like(u)
    e1 = big - ramp_r  # error left when the ramp ends (a·τ, or |u| without one)
    te = np.maximum(t - t1, 0.0)
    rate = ramp_r + e1 * (1.0 - np.exp(-te / tau))
    length = ramp_l + ramp_r * te + e1 * (te - tau * (1.0 - np.exp(-te / tau)))
    return s * rate, s * length


def _rk4(r0, u_of_k, n_chunks, tau, a, dt=1e-5):
    """Integrate ṙ = clip((u − r)/τ, ±a) and l̇ = r by RK4; u constant over each chunk."""
    r, length, out = np.array(r0, float), np.zeros(len(r0)), []
    per_chunk = round(CHUNK / dt)
    for k in range(n_chunks):
        u = u_of_k(k)

        def f(x, u=u):
            return np.clip((u - x) / tau, -a, a)

        for _ in range(per_chunk):
            k1 = f(r)
            k2 = f(r + 0.5 * dt * k1)
            k3 = f(r + 0.5 * dt * k2)
            k4 = f(r + dt * k3)
            # RK4 on the pair (r, l), l̇ = r: the stage values of l̇ are the stage rates
            stages = r + 2 * (r + 0.5 * dt * k1) + 2 * (r + 0.5 * dt * k2) + (r + dt * k3)
            length = length + dt / 6.0 * stages
            r = r + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append((r.copy(), length.copy()))
    return out


def _advance_chunks(physics, u_of_k, n_chunks):
    """Advance chunk by chunk; (rates, paid-out lengths) at each chunk end."""
    l0_start, out = physics.rest_lengths, []
    for k in range(n_chunks):
        physics.advance(CHUNK, u_of_k(k))
        out.append((physics.winch_rates, physics.rest_lengths - l0_start))
    return out


@pytest.mark.parametrize(
    ("bandwidth", "accel"), [(F_HZ, ACCEL), (F_HZ, math.inf), (math.inf, ACCEL)]
)
def test_step_response_is_first_order_with_a_slew_limited_start(bandwidth, accel):
    physics, _, u = _robot(WinchRealism(bandwidth_hz=bandwidth, max_accel=accel))
    assert np.all(physics.winch_rates == 0.0)  # at rest after reset
    tau = 1.0 / (2.0 * math.pi * bandwidth)
    if math.isfinite(accel) and math.isfinite(bandwidth):  # both regimes are exercised
        assert np.any(np.abs(u) > 2 * accel * tau) and np.any(np.abs(u) < accel * tau)
    got = _advance_chunks(physics, lambda k: u, 60)
    for k, (rate, paid) in enumerate(got):
        t = (k + 1) * CHUNK
        if math.isinf(bandwidth):  # slew only: a trapezoid
            want_r = np.sign(u) * np.minimum(accel * t, np.abs(u))
            t1 = np.abs(u) / accel
            want_l = np.sign(u) * np.where(t < t1, 0.5 * accel * t**2, np.abs(u) * (t - 0.5 * t1))
        else:
            want_r, want_l = _step_from_rest(u, t, tau, accel)
        np.testing.assert_allclose(rate, want_r, rtol=0, atol=1e-12, err_msg=f"t = {t}")
        np.testing.assert_allclose(paid, want_l, rtol=0, atol=1e-12, err_msg=f"t = {t}")
    assert np.max(np.abs(got[-1][0] - u)) < 1e-5  # settled on the command after 0.3 s
    if math.isfinite(bandwidth):
        ode = _rk4(np.zeros(8), lambda k: u, 60, tau, accel)
        for (rate, paid), (r_ode, l_ode) in zip(got, ode, strict=True):
            np.testing.assert_allclose(rate, r_ode, rtol=0, atol=1e-10)
            np.testing.assert_allclose(paid, l_ode, rtol=0, atol=1e-11)


def test_ticks_of_several_chunks_end_where_the_closed_form_does():
    """Control ticks of 40 ms (8 chunks each) land on the closed form at the tick ends."""
    physics, _, u = _robot(WinchRealism(bandwidth_hz=F_HZ, max_accel=ACCEL))
    l0 = physics.rest_lengths
    for k in range(1, 8):
        physics.advance(0.04, u)
        want_r, want_l = _step_from_rest(u, 0.04 * k, TAU, ACCEL)
        np.testing.assert_allclose(physics.winch_rates, want_r, rtol=0, atol=1e-12)
        np.testing.assert_allclose(physics.rest_lengths - l0, want_l, rtol=0, atol=1e-12)


def test_ramp_response_lags_by_tau_plus_half_a_hold():
    """Staircase ramp u_k = c·kT (held for T): the zero-order-hold response of a first-order
    system is r_k = c(kT − d(1 − α^k)), α = e^(−T/τ), d = T/(1 − α) = τ(1 + x/2 + x²/12 + …)
    with x = T/τ: the continuous ramp's lag τ plus half a hold."""
    physics, _, u = _robot(WinchRealism(bandwidth_hz=F_HZ))
    slope = u / np.max(np.abs(u)) * 0.1  # c per cable, up to 0.1 m/s²
    got = _advance_chunks(physics, lambda k: slope * k * CHUNK, 80)
    alpha = math.exp(-CHUNK / TAU)
    d = CHUNK / (1.0 - alpha)
    x = CHUNK / TAU
    assert d == pytest.approx(TAU * (1 + x / 2 + x**2 / 12), rel=1e-4)
    for k, (rate, _) in enumerate(got, start=1):
        want = slope * (k * CHUNK - d * (1.0 - alpha**k))
        np.testing.assert_allclose(rate, want, rtol=0, atol=1e-12)
    ode = _rk4(np.zeros(8), lambda k: slope * k * CHUNK, 80, TAU, math.inf)
    for (rate, paid), (r_ode, l_ode) in zip(got, ode, strict=True):
        np.testing.assert_allclose(rate, r_ode, rtol=0, atol=1e-10)
        np.testing.assert_allclose(paid, l_ode, rtol=0, atol=1e-11)


def test_a_ramp_steeper_than_the_acceleration_limit_is_followed_at_that_limit():
    physics, _, u = _robot(WinchRealism(bandwidth_hz=F_HZ, max_accel=ACCEL))
    direction = u / np.max(np.abs(u))
    slope = direction * 5 * ACCEL  # 1 m/s² for the fastest cable
    rates = np.array([r for r, _ in _advance_chunks(physics, lambda k: slope * k * CHUNK, 40)])
    fast = np.abs(direction) > 0.5  # these fall ever further behind, saturated after 25 ms
    np.testing.assert_allclose(
        np.diff(rates[5:, fast], axis=0),
        np.tile(np.sign(slope[fast]) * ACCEL * CHUNK, (34, 1)),
        rtol=1e-9,
    )


def test_the_rate_persists_across_ticks_and_reset_zeroes_it():
    physics, _, u = _robot(WinchRealism(bandwidth_hz=F_HZ))
    physics.advance(0.02, u)
    r_end = physics.winch_rates
    np.testing.assert_allclose(r_end, u * (1 - math.exp(-0.02 / TAU)), rtol=1e-12)
    l0 = physics.rest_lengths
    physics.advance(0.03, np.zeros(8))  # the rate decays from where it was, not from zero
    np.testing.assert_allclose(physics.winch_rates, r_end * math.exp(-0.03 / TAU), rtol=1e-12)
    coasted = r_end * TAU * (1 - math.exp(-0.03 / TAU))
    np.testing.assert_allclose(physics.rest_lengths - l0, coasted, rtol=1e-9)
    physics.reset(paper_pose("p1"))
    assert np.all(physics.winch_rates == 0.0)
    l0 = physics.rest_lengths
    physics.advance(0.02, u)  # the same step response again, from rest
    np.testing.assert_allclose(physics.winch_rates, r_end, rtol=1e-12)
    np.testing.assert_allclose(
        physics.rest_lengths - l0, _step_from_rest(u, 0.02, TAU, math.inf)[1], rtol=0, atol=1e-12
    )


def test_ideal_winches_apply_the_command_at_once():
    physics, _, u = _robot(WinchRealism())
    l0 = physics.rest_lengths
    physics.advance(0.04, u)
    assert np.array_equal(physics.winch_rates, u)
    assert np.array_equal(physics.data.ctrl, u)
    np.testing.assert_allclose(physics.rest_lengths - l0, 0.04 * u, rtol=0, atol=1e-13)


def test_the_range_check_uses_the_lengths_the_loop_reaches():
    """A command an instant winch could not run without leaving its range (3 m) is fine for a
    lagging one when the lag keeps it inside, and refused when it does not."""
    physics, _, _ = _robot(WinchRealism(bandwidth_hz=F_HZ))
    instant, _, _ = _robot(WinchRealism())
    room = 3.0 - physics.rest_lengths.max()
    u = np.full(8, 0.5)
    steps = physics.steps_in(round((room / 0.5 + TAU / 2) / 0.0005) * 0.0005)  # lag 8 mm
    with pytest.raises(ValueError, match="outside the winch range"):
        instant.set_winch_rates(u, steps)
    physics.set_winch_rates(u, steps)
    with pytest.raises(ValueError, match="outside the winch range"):
        physics.set_winch_rates(u, steps + round(TAU / 0.0005))
    with pytest.raises(ValueError, match="exceed the winches' range"):
        physics.set_winch_rates(np.full(8, 0.6), 1)


# ------------------------------------------------------------------ encoders
def _sensors(physics, nominal, winch, seed, home=True):
    s = Sensors(
        physics,
        nominal,
        0.0,
        camera=False,
        home_encoders=home,
        realism=Realism(winch=winch),
        robot_seed=seed,
    )
    s.home(paper_pose("p1"))
    return s


def test_the_encoder_counts_quanta_of_2pi_r_over_n():
    w = WinchRealism(encoder_counts=4096, drum_radius=0.02)
    physics, nominal, u = _robot(w)
    enc = _sensors(physics, nominal, w, 0)
    quantum = 2 * math.pi * 0.02 / 4096  # 30.7 µm of cable per count
    assert enc.encoders.quantum == pytest.approx(quantum, rel=1e-15)
    home, l0 = enc.encoder_lengths, physics.rest_lengths
    readings, paid = [], []
    for _ in range(40):
        physics.advance(CHUNK, u)
        readings.append(enc.encoder_lengths - home)
        paid.append(physics.rest_lengths - l0)
    readings, paid = np.array(readings), np.array(paid)
    counts = readings / quantum
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-6)
    assert np.all(paid - readings >= -1e-12) and np.all(paid - readings < quantum)  # floor
    assert np.max(np.abs(counts)) > 20


@pytest.mark.parametrize("seed", [3, 11])
def test_the_encoder_error_after_paying_out_L_is_L_dr_over_r(seed):
    w = WinchRealism(encoder_counts=4096, drum_radius=0.02, drum_radius_error_std=0.01)
    physics, nominal, u = _robot(w, seed)
    r_true = physics.drum_radius_true
    assert np.all(r_true != 0.02)
    enc = _sensors(physics, nominal, w, seed)
    home, l0 = enc.encoder_lengths, physics.rest_lengths
    for _ in range(25):  # 1 s of platform motion: up to 2 cm of cable per winch
        physics.advance(0.04, 2 * u)
    paid = physics.rest_lengths - l0
    error = (enc.encoder_lengths - home) - paid
    expected = -paid * (r_true - 0.02) / r_true
    quantum = 2 * math.pi * 0.02 / 4096
    assert np.all(error <= expected + 1e-12) and np.all(error > expected - quantum)
    assert np.max(np.abs(expected)) > 3 * quantum  # the radius error, not the count, dominates
    # and which of the two is right: the servo turns the drum by the command over the nominal
    # radius, so the encoder reads what was commanded while the cable paid out r'/r of it
    commanded = 25 * 0.04 * 2 * u
    np.testing.assert_allclose(paid, commanded * r_true / 0.02, rtol=1e-9, atol=1e-12)
    reading = enc.encoder_lengths - home
    assert np.all(reading <= commanded + 1e-12) and np.all(reading > commanded - quantum)


def test_homing_reads_the_nominal_rest_lengths_at_the_home_pose():
    w = WinchRealism(encoder_counts=4096, drum_radius_error_std=0.01)
    physics, nominal, _ = _robot(w, 3)
    T = paper_pose("p1")
    g = nominal.geometry
    l0_nominal = kin.rest_lengths(kin.cable_lengths(g, T, "pulley"), physics.tensions, g.es)
    np.testing.assert_array_equal(_sensors(physics, nominal, w, 3).encoder_lengths, l0_nominal)
    unhomed = _sensors(physics, nominal, w, 3, home=False)
    np.testing.assert_array_equal(unhomed.encoder_lengths, physics.rest_lengths)


def test_drum_radii_are_drawn_per_robot():
    w = WinchRealism(drum_radius=0.02, drum_radius_error_std=0.005)
    a, _, _ = _robot(w, 3)
    b, _, _ = _robot(w, 3)
    c, _, _ = _robot(w, 4)
    assert np.array_equal(a.drum_radius_true, b.drum_radius_true)
    assert not np.array_equal(a.drum_radius_true, c.drum_radius_true)
    rel = np.concatenate(
        [draw_drum_radii(w, robot_rng(s, "winch"), 8) / 0.02 - 1 for s in range(500)]
    )
    assert abs(rel.mean()) < 4 * 0.005 / math.sqrt(rel.size)
    assert rel.std() == pytest.approx(0.005, rel=0.05)
    ideal, _, _ = _robot(WinchRealism(), 3)  # the radius is the robot's (robot.toml: 20 mm)
    assert np.all(ideal.drum_radius_true == load_robot(ACROBOT_TOML).drum_radius)


def test_the_drum_radius_and_the_sensors_spec_are_the_robots():
    # the robot description's numbers (models/acrobot/robot.toml, from the paper §IV-A)
    physics, nominal, _ = _robot(WinchRealism(encoder_counts=4096), 3)
    assert physics.winch.drum_radius == 0.02
    sensors = Sensors(physics, nominal, realism=profile("acrobot"), period=0.04)
    t = sensors.tension.realism
    assert (t.range_min, t.range_max, t.noise_std) == (-25.0, 75.0, 0.01)
    assert t.bias_std == 0.24 / math.sqrt(3.0)  # a ±0.24 N bound, rectangular (GUM 4.3.7)
    cogiro = build_robot("cogiro").physics
    assert cogiro.winch.drum_radius == 0.0675


@pytest.mark.parametrize("set_to", ["truth", "half-way"])
def test_drives_and_encoders_set_to_calibrated_radii(set_to):
    """A drive set to radius r_c turns its drum by the command over r_c: the cable pays out
    r'/r_c of the command; its encoder reports r_c × the counted angle, i.e. r_c/r' of the
    cable. Set to the true radii, both are exact (to the count)."""
    w = WinchRealism(encoder_counts=4096, drum_radius=0.02, drum_radius_error_std=0.01)
    physics, nominal, u = _robot(w, 3)
    r_true = physics.drum_radius_true
    r_set = r_true if set_to == "truth" else 0.5 * (r_true + 0.02)
    physics.set_drum_radii(r_set)
    enc = _sensors(physics, nominal, w, 3)
    home, l0 = enc.encoder_lengths, physics.rest_lengths
    for _ in range(25):
        physics.advance(0.04, 2 * u)
    commanded = 25 * 0.04 * 2 * u
    paid = physics.rest_lengths - l0
    np.testing.assert_allclose(paid, commanded * r_true / r_set, rtol=1e-9, atol=1e-12)
    expected = paid * r_set / r_true  # the reading: what the counts stand for at r_c
    quantum = 2 * math.pi * r_set / 4096
    reading = enc.encoder_lengths - home
    assert np.all(reading <= expected + 1e-12) and np.all(reading > expected - quantum)
    if set_to == "truth":
        np.testing.assert_allclose(paid, commanded, rtol=1e-9, atol=1e-12)
