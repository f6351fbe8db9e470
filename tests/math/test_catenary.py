"""Irvine's elastic catenary against a discretised stretchable cable built in MuJoCo.

Truth: N point masses joined by MuJoCo tendon springs (cdpr_twin/sim/cable_chain.py), of the
same mass, E·S and unstretched length, at rest under MuJoCo's own spring and gravity forces:
their end forces converge to the catenary's as N grows (a lumped chain's error falls as 1/N²).
"""

import math

import numpy as np
import pytest

from cdpr_twin.math.catenary import CatenaryError, end_forces, solve_catenary
from cdpr_twin.sim.cable_chain import chain_end_forces

RHO, ES = 0.064, 68.5e9 * math.pi * 0.002**2  # CoGiRo's Ø 4 mm steel cable
LOW, HIGH = np.zeros(3), np.array([12.0, 5.0, 9.0])  # a 17 m span, 9 m rise
L0 = float(np.linalg.norm(HIGH)) * (1 - 1e-4)  # ≈ 130 N horizontal tension, 0.12 m sag


def _catenary(l0=L0):
    cat = solve_catenary(l0, ES, RHO * 9.81, math.hypot(*HIGH[:2]), HIGH[2])
    return cat, *end_forces(cat, HIGH, LOW)


def test_mujoco_cable_end_forces_converge_to_the_catenary():
    _, on_low, on_high = _catenary()
    errors = []
    for n in (4, 8, 16, 32):
        chain = chain_end_forces(L0, ES, RHO, LOW, HIGH, n)
        errors.append(
            max(
                np.linalg.norm(chain.force_low - on_low) / np.linalg.norm(on_low),
                np.linalg.norm(chain.force_high - on_high) / np.linalg.norm(on_high),
            )
        )
    # measured 1.6e-2, 4.0e-3, 9.9e-4, 2.5e-4: each halving of the segments quarters the error
    assert errors[-1] < 0.01
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    np.testing.assert_allclose(ratios, 4.0, rtol=0.05)
    # the two ends share the cable's weight: V_high − V_low = ρ g L0
    assert on_low[2] - (-on_high[2]) == pytest.approx(-RHO * 9.81 * L0, rel=1e-12)


def test_catenary_limits_and_the_issues_numbers():
    # a taut, light cable is the straight elastic one: τ = E·S (chord − L0) / L0
    chord = float(np.linalg.norm(HIGH))
    cat = solve_catenary(chord / 1.001, ES, 1e-9, math.hypot(*HIGH[:2]), HIGH[2])
    assert cat.tension_low == pytest.approx(ES * 0.001, rel=1e-6)
    assert cat.sag < 1e-9
    # a 17.6 m level cable at 1 kN sags ≈ 23 mm and its arc is ≈ 0.08 mm over the chord
    w, span = RHO * 9.81, 17.6
    lo, hi = span * (1 - 2e-3), span
    for _ in range(60):  # the unstretched length that gives 1 kN horizontal tension
        mid = 0.5 * (lo + hi)
        lo, hi = (
            (mid, hi) if solve_catenary(mid, ES, w, span, 1e-9).horizontal > 1000 else (lo, mid)
        )
    l0 = 0.5 * (lo + hi)
    cat = solve_catenary(l0, ES, w, span, 1e-9)
    assert cat.sag == pytest.approx(w * l0 * span / (8 * 1000), rel=2e-4)  # parabola: 24.3 mm
    assert (cat.length - span) * 1e3 == pytest.approx(8 * cat.sag**2 / (3 * span) * 1e3, rel=1e-2)
    with pytest.raises(CatenaryError):
        solve_catenary(1.0, ES, w, 0.0, 0.5)
