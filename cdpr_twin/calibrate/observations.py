"""What a calibration's recording holds: the readings at K static poses (numpy only)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Observations:
    """What the robot recorded at K static poses (no truth in it).

    Attributes:
        encoder: (K, m) encoder lengths [m].
        tensions: (K, m) tension readings [N].
        taut: (K, m) readings to use (cables taut, readings not clipped).
        T_cam_tag: (K, 4, 4) detected tag poses (pupil frame; anything where not seen).
        seen: (K,) whether the tag was detected at pose k.
        T_guess: (K, 4, 4) the poses the robot was commanded to (the solver's start).
        home: (K,) the readings taken where the encoders were homed: the robot stood at its
            ``T_guess`` there, within the homing's repeatability (``None``: none).
    """

    encoder: np.ndarray
    tensions: np.ndarray
    taut: np.ndarray
    T_cam_tag: np.ndarray
    seen: np.ndarray
    T_guess: np.ndarray
    home: np.ndarray | None = None

    @property
    def homed(self) -> np.ndarray:
        """(K,) bool: :attr:`home`, all False when ``None``."""
        return np.zeros(self.n_poses, bool) if self.home is None else np.asarray(self.home, bool)

    @property
    def n_poses(self) -> int:
        """Number of poses K."""
        return self.encoder.shape[0]

    @property
    def redundancy(self) -> np.ndarray:
        """(K,) equations beyond the pose's own six unknowns.

        Taut cables, + 6 with the tag, + 6 at the homed pose (its prior). The wrench balance's
        rows are not counted (on a robot with more than six cables, a pose with all cables taut
        has redundant lengths anyway). A pose without any (e.g. six taut cables and no tag) is
        fitted exactly whatever the shared parameters are: it carries no information on them,
        and where its six cables are ill-conditioned it only slows the solver down.
        """
        return self.taut.sum(axis=1) + 6 * (self.seen.astype(int) + self.homed) - 6

    def subset(self, keep: np.ndarray) -> Observations:
        """The observations at the poses ``keep`` (a (K,) mask or indices) selects."""
        return Observations(
            self.encoder[keep],
            self.tensions[keep],
            self.taut[keep],
            self.T_cam_tag[keep],
            self.seen[keep],
            self.T_guess[keep],
            self.homed[keep],
        )
