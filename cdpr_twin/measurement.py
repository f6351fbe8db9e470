"""What the robot's sensors report at one instant: the only input of estimators."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_twin.vision import TagDetection


@dataclass(frozen=True, eq=False)
class Measurement:
    """One sensor snapshot, as a real ACROBOT would log it (plus the twin's ground truth).

    Attributes:
        time: simulation time [s].
        cable_lengths: (m,) encoder readings: each winch's unstretched paid-out length l0_i,
            homed at the start pose to the nominal model's value there [m].
        tensions: (m,) tension-sensor readings at B_i, noise included [N].
        cable_rates: (m,) last commanded winch rates dl0/dt [m/s].
        twist_platform: (6,) last commanded platform twist ᵖv_p = [v, ω] in F_p [m/s, rad/s],
            or ``None`` when the command was given as cable rates only.
        T_base_platform_true: (4, 4) ground-truth platform pose (the C-Track's role). Estimators
            must not read it; it is here so that one record carries truth and sensors together.
        image: (H, W, 3) RGB uint8 frame of the onboard camera, or ``None`` (camera off).
        tag: the tag detected in ``image``, or ``None`` (camera off, or tag not found).
    """

    time: float
    cable_lengths: np.ndarray
    tensions: np.ndarray
    cable_rates: np.ndarray
    twist_platform: np.ndarray | None
    T_base_platform_true: np.ndarray
    image: np.ndarray | None = None
    tag: TagDetection | None = None

    def __post_init__(self) -> None:
        for name in (
            "cable_lengths",
            "tensions",
            "cable_rates",
            "twist_platform",
            "T_base_platform_true",
            "image",
        ):
            value = getattr(self, name)
            if value is not None:
                value = np.array(value)
                value.flags.writeable = False
                object.__setattr__(self, name, value)

    @property
    def camera_on(self) -> bool:
        """Whether this measurement carries a camera frame."""
        return self.image is not None
