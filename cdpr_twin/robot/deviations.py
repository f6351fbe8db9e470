"""The robot's calibration errors ("truth deviations"): magnitudes, and one robot's draw.

Pure values (numpy only): scenarios carry a :class:`DeviationSpec`; the simulation layer applies
the :class:`TruthDeviations` it draws to the twin's model, never to the nominal geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class TruthDeviations:
    """Concrete calibration errors of one simulated robot (all zero: the nominal robot).

    Attributes:
        exit_offsets: (m, 3) offsets of the exit points A_i in F_b [m].
        anchor_offsets: (m, 3) offsets of the anchor points B_i in F_p [m].
        es_scale: (m,) factors on each cable's E·S.
        pulley_radius_offsets: (m,) offsets of each sheave radius [m].
        camera_offset: (6,) camera mounting error [δp (m), δθ (rad)] in the platform frame.
        tag_offset: (6,) tag placement error [δp (m), δθ (rad)] in the base frame.
    """

    exit_offsets: np.ndarray
    anchor_offsets: np.ndarray
    es_scale: np.ndarray
    pulley_radius_offsets: np.ndarray
    camera_offset: np.ndarray
    tag_offset: np.ndarray

    @classmethod
    def zero(cls, n_cables: int) -> TruthDeviations:
        """No deviation: the twin is the nominal robot."""
        return cls(
            np.zeros((n_cables, 3)),
            np.zeros((n_cables, 3)),
            np.ones(n_cables),
            np.zeros(n_cables),
            np.zeros(6),
            np.zeros(6),
        )


@dataclass(frozen=True)
class DeviationSpec:
    """Magnitudes (standard deviations) of the robot's calibration errors, and the robot seed.

    One seed draws one robot: keep it fixed across repeated runs, like one physical robot.

    Attributes:
        exit_point_std: per-axis std of the exit point offsets [m].
        anchor_point_std: per-axis std of the anchor point offsets [m].
        es_scale_std: relative std of each cable's E·S.
        pulley_radius_std: std of each sheave radius [m].
        camera_position_std: per-axis std of the camera position [m].
        camera_rotation_std: per-axis std of the camera orientation [rad].
        tag_position_std: per-axis std of the tag position [m].
        tag_rotation_std: per-axis std of the tag orientation [rad].
        seed: robot seed.
    """

    exit_point_std: float = 0.0
    anchor_point_std: float = 0.0
    es_scale_std: float = 0.0
    pulley_radius_std: float = 0.0
    camera_position_std: float = 0.0
    camera_rotation_std: float = 0.0
    tag_position_std: float = 0.0
    tag_rotation_std: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if name != "seed" and not (np.isfinite(value) and value >= 0):
                raise ValueError(f"DeviationSpec.{name} must be a finite std ≥ 0, got {value}")

    def draw(self, n_cables: int) -> TruthDeviations:
        """Draw the deviations of the robot this spec's seed names (deterministic).

        Args:
            n_cables: the robot's cable count m (the draw depends on it).
        """
        rng = np.random.default_rng(self.seed)
        return TruthDeviations(
            exit_offsets=rng.normal(0.0, self.exit_point_std, (n_cables, 3)),
            anchor_offsets=rng.normal(0.0, self.anchor_point_std, (n_cables, 3)),
            es_scale=np.clip(1.0 + rng.normal(0.0, self.es_scale_std, n_cables), 0.2, None),
            pulley_radius_offsets=rng.normal(0.0, self.pulley_radius_std, n_cables),
            camera_offset=np.concatenate(
                [
                    rng.normal(0.0, self.camera_position_std, 3),
                    rng.normal(0.0, self.camera_rotation_std, 3),
                ]
            ),
            tag_offset=np.concatenate(
                [
                    rng.normal(0.0, self.tag_position_std, 3),
                    rng.normal(0.0, self.tag_rotation_std, 3),
                ]
            ),
        )
