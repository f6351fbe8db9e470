"""Winch encoders: the cable length each winch reports, homed at a known pose.

Ideal (``WinchRealism()``): the encoder reads the winch's unstretched paid-out length l0 plus
the homing offset, exactly.

Otherwise each encoder counts its drum's angle θ from where it was homed, with
``encoder_counts`` counts per revolution (a counter: the count is floor(θ·N/2π), zeroed at
homing), and reports the length the radius r it is set to (the nominal one, or a calibrated
description's: :attr:`Physics.drum_radius_set`) would pay out over the counted angle, while
the cable actually paid out is the *true* radius r' times θ (:attr:`Physics.drum_radius_true`,
drawn per robot). After paying out L the reading has moved by L·r/r' (less up to one count,
2π·r/N): an error ≈ −L·δr/r' that grows with paid-out cable.
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import cable_lengths, rest_lengths
from cdpr_twin.robot.realism import WinchRealism
from cdpr_twin.sim.physics import Physics


class Encoders:
    """The winch encoders of one robot.

    Args:
        physics: the simulated robot (its true drum radii, drawn once per robot by
            :func:`cdpr_twin.sim.winch.draw_drum_radii`).
        nominal: the nominal geometry (homing reads its rest lengths at the home pose).
        realism: winch and encoder imperfections.
        home: home at :meth:`home` (else read the true rest lengths).
    """

    def __init__(
        self,
        physics: Physics,
        nominal: CdprGeometry,
        realism: WinchRealism,
        home: bool = True,
    ) -> None:
        self.physics, self.nominal, self.realism, self.home_enabled = (
            physics,
            nominal,
            realism,
            home,
        )
        self._offset = np.zeros(physics.n_cables)
        self._l0_home = np.zeros(physics.n_cables)  # true paid-out lengths when homed [m]
        # the motors' positions when homed [m]
        self._motor_home: np.ndarray | None = None
        # (m,) jumps of the readings since homing [m], or None
        self._glitch: np.ndarray | None = None

    def glitch(self, i: int, jump: float) -> None:
        """Encoder i (from 0) jumps by ``jump`` [m]: every later reading is off by it."""
        if self._glitch is None:
            self._glitch = np.zeros(self.physics.n_cables)
        self._glitch[i] += jump

    @property
    def ideal(self) -> bool:
        """Exact encoders on drums whose radii are the ones they are set to."""
        return self.realism.encoder_counts == 0 and self.physics.drums_as_set

    @property
    def quantum(self) -> float:
        """The length one count stands for at the nominal radius, 2π·r/N [m] (0: exact)."""
        n = self.realism.encoder_counts
        return 2.0 * math.pi * self.realism.drum_radius / n if n else 0.0

    def home(self, T_base_platform: np.ndarray, tensions: np.ndarray) -> None:
        """Zero the encoders at a known pose (the paper's "initial pose is known").

        They then read the rest lengths the nominal model predicts at that pose with the given
        tensions, plus whatever the winches pay out afterwards (as the encoders measure it).
        Without homing (``home=False``) they read the true rest lengths now, plus the same.
        """
        self._offset = np.zeros(self.physics.n_cables)
        self._l0_home = self.physics.rest_lengths
        motor = self.physics.motor_positions
        self._motor_home = None if motor is None else motor
        self._glitch = None
        if self.home_enabled:
            g = self.nominal
            l0_nominal = rest_lengths(cable_lengths(g, T_base_platform, "pulley"), tensions, g.es)
            self._offset = l0_nominal - self.physics.rest_lengths

    def home_lengths(self, readings: np.ndarray) -> None:
        """Zero the encoders so that they read ``readings`` (m,) [m] now.

        The drums were homed each on its own reference, then wound to these lengths.
        """
        self.home_enabled = True
        self._l0_home = self.physics.rest_lengths
        self._motor_home = self.physics.motor_positions
        self._glitch = None
        self._offset = np.asarray(readings, dtype=float) - self._l0_home

    def read(self) -> np.ndarray:
        """The lengths the encoders report (m,) [m]."""
        if self.ideal:  # (exact encoders on drums as set: the length itself, bit for bit)
            lengths = self.physics.rest_lengths + self._offset
        else:
            lengths = self._l0_home + self._offset + self.measured_payout()
        return lengths if self._glitch is None else lengths + self._glitch

    def measured_payout(self) -> np.ndarray:
        """The length the encoders count as paid out since homing (m,) [m].

        The drum angle θ = ΔL/r' (ΔL the true paid-out length, r' the true radius), counted
        as floor(θ·N/2π) counts and reported as the radius the encoders are set to (nominal,
        or a calibration's: :meth:`Physics.set_drum_radii`) × counted angle.
        """
        w, motor = self.realism, self.physics.motor_positions
        if motor is not None:  # an encoder on the motor counts the motor's angle
            theta = (motor - self._motor_home) / self.physics.drum_radius_set
        else:
            theta = (self.physics.rest_lengths - self._l0_home) / self.physics.drum_radius_true
        if w.encoder_counts:
            step = 2.0 * math.pi / w.encoder_counts
            theta = np.floor(theta / step) * step
        return self.physics.drum_radius_set * theta
