"""Drums and gearboxes: how a motor's turn becomes cable past the guide (numpy only).

Each winch is a motor, a gearbox with play, and a grooved drum (:class:`DriveRealism`). The
velocity loop turns the motor; its angle is what the encoder counts. The cable the drum then
pays out past the first fixed guide, per winch (SI units, angles in radians):

- **gearbox backlash** b (as cable length at the drum): the drum's position x_d (= r·φ_d)
  stays within ±b/2 of the motor's x_m (= r_set·φ_m). While the cable pulls harder than
  ``drum_holding_force`` it keeps the drum against the flank that holds it, x_d = x_m + b/2
  (paying out is the way the cable pulls); a drum that left that flank (its cable went slack)
  stays where it is until the motor's flank pushes it or its cable pulls it back out (the
  play operator): a reversal of the motor then moves a slack cable's drum only after the
  motor has crossed the play, a dead band of width b.
- **helical groove** of pitch p on a drum of radius r at a guide distance D: the cable lies on
  a helix, √(r² + (p/2π)²) per radian of drum, and departs the drum at x(φ) = x₀ + p·φ/2π
  along its axis, so the free span to the guide is s(φ) = √(D² + x(φ)²). The cable past the
  guide is what the drum paid out less what the span took:

      Δl = √(r² + (p/2π)²)·Δφ − (s(φ + Δφ) − s(φ)).

- **force-dependent winding**: the rope flattens on the drum as its force τ rises, so its
  centre line winds on a smaller radius: r(τ) = r'·(1 − κ·τ) (r' the drum's true effective
  radius at no load), τ taken at the start of each physics chunk (≤ 5 ms).

:class:`Drums` holds each winch's motor and drum positions across chunks and returns the rest
length each chunk adds. The motors' Coulomb friction acts in the velocity loop
(:func:`cdpr_twin.sim.winch.friction_response`).
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.robot.realism import DriveRealism


def free_span(d: DriveRealism, x: np.ndarray) -> np.ndarray:
    """The free span from the drum's departure point to the guide, √(D² + x²) [m]."""
    return np.hypot(d.guide_distance, x)


def helix_factor(d: DriveRealism, radius: np.ndarray) -> np.ndarray:
    """Cable on the drum per radian of drum over the radius: √(1 + (p/2πr)²)."""
    return np.hypot(1.0, d.helix_pitch / (2.0 * math.pi * radius))


class Drums:
    """The motors, gearboxes and drums of a robot's winches, persistent across chunks.

    Args:
        drive: the drives' imperfections.
        radius_true: (n,) the drums' true effective radii at no load r' [m].
        radius_set: (n,) the radii the drives and encoders are set to [m].

    Attributes:
        motor: (n,) the motors' positions as cable length at the set radius, r_set·φ_m [m].
        drum: (n,) the drums' positions as cable length at the set radius, r_set·φ_d [m].
    """

    def __init__(self, drive: DriveRealism, radius_true: np.ndarray, radius_set: np.ndarray):
        self.drive = drive
        self.radius_true = np.asarray(radius_true, dtype=float)
        self.radius_set = np.asarray(radius_set, dtype=float)
        n = self.radius_true.size
        self.motor, self.drum = np.zeros(n), np.zeros(n)
        self.engaged = np.ones(n, dtype=bool)  # each drum against its cable's flank

    def reset(self) -> None:
        """Motors at their zero, each drum against the flank that holds its cable.

        The cables were wound to their start lengths (reeled in): the motor's flank then pushes
        the drum the way the cable's pull presses it, x_d = x_m + b/2, slack cable or not.
        """
        self.motor = np.zeros_like(self.motor)
        self.drum = np.full_like(self.motor, 0.5 * self.drive.backlash)
        self.engaged = np.ones(self.motor.shape, dtype=bool)

    def drum_after(
        self, motor: np.ndarray, tensions: np.ndarray, stiffness: np.ndarray
    ) -> np.ndarray:
        """Where the drums go when the motors move to ``motor`` (m,) [m] (the play operator).

        A drum against the flank its cable presses it to stays there while the cable pulls
        harder than the holding force. A drum inside the play is pushed by the motor's flanks
        and pulled out by its cable until the cable's force falls to the holding force: by
        (τ − τ_h)/k at most (k = E·S/l0), the quasi-static step of a light drum.

        Args:
            motor: (n,) the motors' new positions [m].
            tensions: (n,) the cables' forces [N].
            stiffness: (n,) the cables' stiffnesses E·S/l0 [N/m].
        """
        half = 0.5 * self.drive.backlash
        excess = np.maximum(0.0, np.asarray(tensions) - self.drive.drum_holding_force)
        free = np.clip(self.drum + excess / stiffness, motor - half, motor + half)
        held = self.engaged & (excess > 0.0)
        return np.where(held, motor + half, free)

    def payout(self, drum0: np.ndarray, drum1: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """Cable paid out past the guide as the drums turn from ``drum0`` to ``drum1`` [m].

        Args:
            drum0: (n,) the drums' positions before [m] (r_set·φ).
            drum1: (n,) after [m].
            tensions: (n,) the cables' forces [N] (the winding radius's load).

        Returns:
            (n,) the rest length each cable gains [m].
        """
        d = self.drive
        phi0, phi1 = drum0 / self.radius_set, drum1 / self.radius_set
        radius = self.radius_true * (1.0 - d.winding_compliance * np.asarray(tensions))
        wound = radius * helix_factor(d, radius) * (phi1 - phi0)
        if d.helix_pitch == 0.0:
            return wound
        walk = d.helix_pitch / (2.0 * math.pi)
        x0, x1 = d.departure_offset + walk * phi0, d.departure_offset + walk * phi1
        return wound - (free_span(d, x1) - free_span(d, x0))

    def advance(
        self, motor_step: np.ndarray, tensions: np.ndarray, stiffness: np.ndarray
    ) -> np.ndarray:
        """Move the motors by ``motor_step`` (n,) [m at the set radius]; the rest lengths gained.

        Args:
            motor_step: (n,) how far each motor turned, r_set·Δφ_m [m].
            tensions: (n,) the cables' forces now [N].
            stiffness: (n,) the cables' stiffnesses E·S/l0 [N/m].

        Returns:
            (n,) the rest length each cable gains past its guide [m].
        """
        self.motor = self.motor + motor_step
        drum = self.drum_after(self.motor, tensions, stiffness)
        gained = self.payout(self.drum, drum, tensions)
        # (np.clip and the flank itself return motor + b/2 exactly: equality is the contact)
        self.drum, self.engaged = drum, drum >= self.motor + 0.5 * self.drive.backlash
        return gained
