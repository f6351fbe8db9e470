"""The robot's sensors: winch encoders (homed), tension sensors, the onboard camera.

They read the :class:`~cdpr_twin.sim.physics.Physics` and produce the :class:`Measurement`
that estimators and controllers see — never ground truth. Each run's noise comes from its own
seeded generator. The tag detector uses the *nominal* (calibrated) intrinsics and tag size, as
a real robot's software would, while the image is rendered from the simulated robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.kinematics import cable_lengths, rest_lengths
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim.model import SimulationError
from cdpr_twin.sim.physics import Physics
from cdpr_twin.types import CameraIntrinsics, Command, Measurement


@dataclass(frozen=True, eq=False)
class NominalRobot:
    """What the robot's software believes: the nominal model's numbers.

    Attributes:
        geometry: nominal geometry (estimators and controllers use it).
        intrinsics: calibrated camera intrinsics, or ``None`` without camera.
        tag_size: edge of the tag's black square [m] (0 without tag).
        T_base_tag: (4, 4) tag pose the model file states (pupil frame), or ``None``.
    """

    geometry: CdprGeometry
    intrinsics: CameraIntrinsics | None
    tag_size: float
    T_base_tag: np.ndarray | None


class Sensors:
    """Encoders, tension sensors and the onboard camera of one simulated robot.

    Args:
        physics: the simulated robot.
        nominal: what the robot's software believes (for homing and tag detection).
        tension_noise_std: std of the Gaussian noise on tension readings [N] (paper: 0.24 N
            accuracy); 0 switches noise off.
        noise_seed: seed of this run's sensor noise.
        camera: render the onboard camera and detect the tag in :meth:`read`.
        home_encoders: :meth:`home` zeroes the encoders the way a real robot is homed at a
            known pose (they then read the nominal model's rest lengths there); without it
            they read the true rest lengths.
    """

    def __init__(
        self,
        physics: Physics,
        nominal: NominalRobot,
        tension_noise_std: float = 0.24,
        noise_seed: int = 0,
        camera: bool = True,
        home_encoders: bool = True,
    ) -> None:
        if not (np.isfinite(tension_noise_std) and tension_noise_std >= 0):
            raise ValueError(f"tension_noise_std must be ≥ 0 N, got {tension_noise_std}")
        self.physics, self.nominal = physics, nominal
        self.tension_noise_std = float(tension_noise_std)
        self._rng = np.random.default_rng(noise_seed)
        self.home_encoders = bool(home_encoders)
        self._encoder_offset = np.zeros(physics.n_cables)
        self._renderer: cam_mod.CameraRenderer | None = None
        self._detector = None
        if camera:
            if not physics.has_camera or nominal.intrinsics is None:
                raise SimulationError(
                    f"{physics.source} has no camera {cam_mod.CAMERA_NAME!r}; "
                    "run with the camera off"
                )
            from cdpr_twin.vision import TagDetector  # OpenCV and pupil-apriltags, on demand

            self._renderer = cam_mod.CameraRenderer(physics.model)
            self._detector = TagDetector(nominal.intrinsics, tag_size=nominal.tag_size)

    @property
    def camera(self) -> bool:
        """Whether the camera renders."""
        return self._renderer is not None

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    @property
    def encoder_lengths(self) -> np.ndarray:
        """What the winch encoders read: rest lengths plus the homing offset. (m,) [m]."""
        return self.physics.rest_lengths + self._encoder_offset

    def home(self, T_base_platform: np.ndarray) -> None:
        """Home the encoders at a known pose (the paper's "initial pose is known").

        With ``home_encoders`` they then read the rest lengths the nominal model predicts at
        that pose with the true tensions, plus whatever the winches pay out afterwards.
        """
        self._encoder_offset = np.zeros(self.physics.n_cables)
        if self.home_encoders:
            g = self.nominal.geometry
            l0_nominal = rest_lengths(cable_lengths(g, T_base_platform, "pulley"),
                                      self.physics.tensions, g.es)  # fmt: skip
            self._encoder_offset = l0_nominal - self.physics.rest_lengths

    def render(self) -> np.ndarray:
        """The onboard camera's current frame, (H, W, 3) RGB uint8."""
        if self._renderer is None:
            raise SimulationError("these sensors were built with camera=False; pass camera=True")
        return self._renderer.render(self.physics.data)

    def read(self, command: Command | None = None, render: bool | None = None) -> Measurement:
        """Read every sensor now.

        Args:
            command: the last command sent to the winches (carried in the measurement).
            render: render the camera and detect the tag; ``None`` does so when the camera is on.

        Returns:
            A frozen :class:`Measurement` (tensions carry this run's seeded noise).
        """
        render = self._renderer is not None if render is None else render
        tensions = self.physics.tensions
        if self.tension_noise_std > 0:
            noise = self._rng.normal(0.0, self.tension_noise_std, self.physics.n_cables)
            tensions = tensions + noise
        image = tag = None
        if render:
            image = self.render()
            tag = self._detector.detect(image)
        return Measurement(
            time=self.physics.time,
            cable_lengths=self.encoder_lengths,
            tensions=tensions,
            command=command,
            image=image,
            tag=tag,
        )
