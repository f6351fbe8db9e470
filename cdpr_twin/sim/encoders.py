"""Winch encoders: the cable length each winch reports, homed at a known pose.

Ideal (``WinchRealism()``): the encoder reads the winch's unstretched paid-out length l0 plus
the homing offset, exactly.
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.kinematics import cable_lengths, rest_lengths
from cdpr_twin.realism import WinchRealism
from cdpr_twin.sim.physics import Physics


class Encoders:
    """The winch encoders of one robot.

    Args:
        physics: the simulated robot.
        nominal: the nominal geometry (homing reads its rest lengths at the home pose).
        realism: winch and encoder imperfections.
        robot_rng: the per-robot generator (drum radius errors).
        home: home at :meth:`home` (else read the true rest lengths).
    """

    def __init__(
        self,
        physics: Physics,
        nominal: CdprGeometry,
        realism: WinchRealism,
        robot_rng: np.random.Generator,
        home: bool = True,
    ) -> None:
        self.physics, self.nominal, self.realism, self.home_enabled = (
            physics,
            nominal,
            realism,
            home,
        )
        self._offset = np.zeros(physics.n_cables)

    def home(self, T_base_platform: np.ndarray, tensions: np.ndarray) -> None:
        """Zero the encoders at a known pose (the paper's "initial pose is known").

        They then read the rest lengths the nominal model predicts at that pose with the given
        tensions, plus whatever the winches pay out afterwards.
        """
        self._offset = np.zeros(self.physics.n_cables)
        if self.home_enabled:
            g = self.nominal
            l0_nominal = rest_lengths(cable_lengths(g, T_base_platform, "pulley"), tensions, g.es)
            self._offset = l0_nominal - self.physics.rest_lengths

    def read(self) -> np.ndarray:
        """The lengths the encoders report (m,) [m]."""
        return self.physics.rest_lengths + self._offset
