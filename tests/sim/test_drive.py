"""Drums, gearboxes and motor friction against independent geometry and closed forms.

- the helical groove: the cable past the guide is the arc length of the 3-D helix the drum
  unwinds (summed here over a fine polyline of its points) less the change of the straight span
  from the departure point to the guide (Pythagoras), through the physics;
- the force-dependent winding radius: the cable paid per motor turn shrinks by κ·τ;
- the backlash: a slack cable's drum stands still over a motor travel of the play's width
  after a reversal, and follows the motor at once while the cable pulls it;
- Coulomb friction in a proportional velocity loop: the textbook first-order step toward
  u − f, the motor stuck for |u| ≤ f, and a reversal through rest.
"""

import math

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.options import OptionError
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.robot.realism import DriveRealism, WinchRealism, profile
from cdpr_twin.sim import Sensors, build_robot
from cdpr_twin.sim.drive import Drums

R = 0.02  # ACROBOT's drum radius (robot.toml) [m]
TICK = 0.04  # control period [s]


def _physics(drive, winch=None):
    built = build_robot(deviations=DeviationSpec(seed=0), winch=winch, drive=drive)
    built.physics.reset(paper_pose("p1"))
    return built


def _helix_polyline_length(r, pitch, phi):
    """Arc length of the helix (r cos φ, r sin φ, p φ/2π) over [0, φ], as a fine polyline."""
    t = np.linspace(0.0, phi, 200_001)
    pts = np.stack([r * np.cos(t), r * np.sin(t), pitch * t / (2 * math.pi)], axis=1)
    return np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()


def test_the_helical_groove_pays_the_helix_less_the_span_it_takes():
    pitch, guide, x0 = 0.01, 0.05, 0.01  # coarse on purpose: millimetres of effect
    drive = DriveRealism(helix_pitch=pitch, guide_distance=guide, departure_offset=x0)
    built = _physics(drive)
    p = built.physics
    sensors = Sensors(p, built.nominal, 0.0, camera=False)
    sensors.home(paper_pose("p1"))
    read0, l0 = sensors.encoder_lengths, p.rest_lengths
    u = np.zeros(p.n_cables)
    u[0] = 0.2  # cable 1 out (it goes slack; the others hold the platform)
    for _ in range(25):
        p.advance(TICK, u)
    phi = np.where(u > 0, 25 * TICK * 0.2 / R, 0.0)  # the drums' turns [rad]
    x1 = x0 + pitch * phi / (2 * math.pi)
    span_change = np.hypot(guide, x1) - math.hypot(guide, x0)
    expected = [_helix_polyline_length(R, pitch, a) for a in phi] - span_change
    # the polyline's chord error is ~(Δt)²·r/24 per segment: ≪ 1e-9 m over 2e5 segments
    assert np.allclose(p.rest_lengths - l0, expected, rtol=0, atol=1e-9)
    assert span_change[0] > 5e-3  # the span took 5 mm: the check can fail
    # the encoder (on the motor) reads the command, not the cable
    assert np.allclose(sensors.encoder_lengths - read0, 25 * TICK * u, rtol=0, atol=1e-12)


def test_the_winding_radius_shrinks_with_the_cables_force():
    kappa = 4e-5
    drums = Drums(DriveRealism(winding_compliance=kappa), np.full(2, R), np.full(2, R))
    tensions = np.array([0.0, 75.0])
    drums.reset()
    paid = drums.advance(np.full(2, 0.1), tensions, np.full(2, 3e5))
    # no load: the drum's own radius; at 75 N the rope's centre line sits 0.3 % lower
    assert paid[0] == pytest.approx(0.1, abs=1e-15)
    assert paid[1] / paid[0] == pytest.approx(1.0 - 0.003, abs=1e-12)


def test_backlash_is_a_dead_band_of_its_width_on_a_reversal_of_a_slack_cable():
    b = 0.002
    drive = DriveRealism(backlash=b, drum_holding_force=1.0)
    built = _physics(drive)
    p = built.physics
    p.disable_cable(0)  # no force holds drum 1 against a flank
    u = np.zeros(p.n_cables)
    rate = 0.01  # 0.4 mm per tick
    l0 = [p.rest_lengths]
    motor = [p.motor_positions]
    for k in range(30):
        u[0] = rate if k < 10 else -rate
        p.advance(TICK, u)
        l0.append(p.rest_lengths)
        motor.append(p.motor_positions)
    l0, motor = np.array(l0)[:, 0], np.array(motor)[:, 0]
    # out: the drum was left on the paying-out flank (b/2 ahead of the motor): the motor
    # crosses the whole play before its other flank pushes the drum on
    assert l0[10] - l0[0] == pytest.approx(motor[10] - b, abs=1e-12)
    # reversal: the drum stands still until the motor has crossed the whole play b
    still = np.abs(l0 - l0[10]) < 1e-15
    back = motor[10] - motor
    assert np.all(still[back <= b - 1e-12][10:])
    assert not np.any(still[back >= b + 1e-12][10:])
    assert l0[-1] - l0[10] == pytest.approx(-(back[-1] - b), abs=1e-12)


def test_a_taut_cable_follows_the_motor_through_a_reversal():
    b = 0.002
    built = _physics(DriveRealism(backlash=b, drum_holding_force=1.0))
    p = built.physics
    l0 = p.rest_lengths
    assert np.all(p.tensions > 1.0)
    u = np.full(p.n_cables, 0.005)
    p.advance(TICK, u)
    p.advance(TICK, -u)
    # back where it started, as a backlash-free drum: the cable keeps the play closed
    assert np.allclose(p.rest_lengths - l0, 0.0, atol=1e-12)


def test_coulomb_friction_in_the_velocity_loop():
    f_hz, lag = 10.0, 0.002
    tau = 1.0 / (2 * math.pi * f_hz)
    winch = WinchRealism(bandwidth_hz=f_hz)
    p = _physics(DriveRealism(friction_rate=lag), winch).physics
    l0 = p.rest_lengths
    # below the friction's rate the resting motor does not start
    p.advance(TICK, np.full(p.n_cables, 0.9 * lag))
    assert np.all(p.rest_lengths == l0) and np.all(p.winch_rates == 0.0)
    # above it: a first-order step toward u − f (textbook), from rest
    u, t = 0.01, 3 * TICK
    p.advance(3 * TICK, np.full(p.n_cables, u))
    e = u - lag
    assert np.allclose(p.winch_rates, e * -math.expm1(-t / tau), rtol=0, atol=1e-12)
    moved = e * (t + tau * math.expm1(-t / tau))
    assert np.allclose(p.rest_lengths - l0, moved, rtol=0, atol=1e-12)
    # a reversal: while it still moves forward friction adds to the braking (target −u − f);
    # it stops at t0 = τ ln((r0 + u + f)/(u + f)) and starts back toward −u + f
    r0, x0 = float(p.winch_rates[0]), float(p.rest_lengths[0])
    p.advance(TICK, np.full(p.n_cables, -u))
    t0 = tau * math.log((r0 + u + lag) / (u + lag))
    a = -u - lag
    x_stop = a * t0 + (r0 - a) * tau * -math.expm1(-t0 / tau)
    t1, b = TICK - t0, -u + lag
    x_back = b * (t1 + tau * math.expm1(-t1 / tau))
    assert p.rest_lengths[0] - x0 == pytest.approx(x_stop + x_back, abs=1e-12)
    assert p.winch_rates[0] == pytest.approx(b * -math.expm1(-t1 / tau), abs=1e-12)


def test_friction_needs_a_velocity_loop():
    with pytest.raises(OptionError, match=r"realism\.drive\.friction_rate"):
        build_robot(drive=DriveRealism(friction_rate=1e-3))


def test_the_full_profile_winds_the_drums_and_acrobot_does_not():
    full, acro = profile("acrobot_full"), profile("acrobot")
    assert full.drive.drums and not acro.drive.drums and acro.drive == DriveRealism()
    p = _physics(full.drive, full.winch).physics
    assert p.motor_positions is not None


def test_a_winding_compliance_that_would_shrink_the_drum_by_a_tenth_is_refused():
    """r(τ) = r′(1 − κτ): at CoGiRo's 5 kN ceiling κ = 2e-4 /N winds on no radius at all."""
    import tomllib

    from cdpr_twin.resources import robot_description

    description = robot_description("cogiro")
    scene = description.parent / "scene.xml"
    tau_max = tomllib.loads(description.read_text())["winches"]["tension_range_n"][1]
    kappa = 2e-4
    assert kappa * tau_max >= 1.0  # the radius this κ would give is ≤ 0
    with pytest.raises(OptionError) as err:
        build_robot(scene, drive=DriveRealism(winding_compliance=kappa))
    message = str(err.value)
    assert "realism.drive.winding_compliance" in message and "\n" not in message
