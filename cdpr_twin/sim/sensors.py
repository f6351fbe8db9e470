"""The robot's sensors: winch encoders (homed), tension sensors, the onboard camera.

They read the :class:`~cdpr_twin.sim.physics.Physics` and produce the :class:`Measurement`
that estimators and controllers see — never ground truth. The run's reading noise comes from
its own seeded generators, each robot's calibration errors from the truth seed. The tag detector
uses the *nominal* (calibrated) intrinsics and tag size, as a real robot's software would,
while the image is rendered from the simulated robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, cast

import numpy as np

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.robot.realism import Realism, for_robot, robot_rng, run_rng
from cdpr_twin.sim.encoders import Encoders
from cdpr_twin.sim.model import ModelError, SimulationError, robot_sensing
from cdpr_twin.sim.onboard_camera import OnboardCamera
from cdpr_twin.sim.physics import Physics
from cdpr_twin.sim.tension_sensors import TensionSensors
from cdpr_twin.types import CameraIntrinsics, Command, Measurement


class _SensedTensions(Protocol):
    """A physics whose tension sensors read other than its straight cables' pull."""

    @property
    def sensed_tensions(self) -> np.ndarray:
        """(m,) the tensions where the sensors sit [N]."""
        ...


@dataclass(frozen=True, eq=False)
class NominalRobot:
    """What the robot's software believes: the nominal model's numbers.

    Attributes:
        geometry: nominal geometry (estimators and controllers use it).
        intrinsics: calibrated camera intrinsics, or ``None`` without camera.
        tag_size: edge of the tag's black square [m] (0 without tag).
        T_base_tag: (4, 4) tag pose the model file states (pupil frame), or ``None``.
        drum_radii: (m,) the drums' radii [m] a calibrated robot description states
            (``drum_radius_m`` × ``drum_radius_scale``): the drives and encoders are set to
            them; ``None``: the robot's own radius.
        rate_range: ((m,), (m,)) the winches' lowest and highest rates [m/s] (the model's
            ``ctrlrange``), or ``None`` when the model names no winch actuators.
    """

    geometry: CdprGeometry
    intrinsics: CameraIntrinsics | None
    tag_size: float
    T_base_tag: np.ndarray | None
    drum_radii: np.ndarray | None = None
    rate_range: tuple[np.ndarray, np.ndarray] | None = None


class Sensors:
    """Encoders, tension sensors and the onboard camera of one simulated robot.

    Args:
        physics: the simulated robot.
        nominal: what the robot's software believes (for homing and tag detection).
        tension_noise_std: std of the Gaussian noise on each tension reading [N]; 0: none.
        noise_seed: the run seed (reading noise).
        camera: render the onboard camera and detect the tag in :meth:`read`.
        home_encoders: :meth:`home` zeroes the encoders the way a real robot is homed at a
            known pose (they then read the nominal model's rest lengths there); without it
            they read the true rest lengths.
        realism: the sensors' imperfections (default: none).
        robot_seed: the truth seed (each robot's calibration errors).
        period: the interval between reads [s] (the control period): frames are exposed over
            the ``exposure_s`` before each read; needed for motion blur.
        tag_window: search the tag near its last detection first (``[sensors] tag_window``).
    """

    def __init__(
        self,
        physics: Physics,
        nominal: NominalRobot,
        tension_noise_std: float = 0.24,
        noise_seed: int = 0,
        camera: bool = True,
        home_encoders: bool = True,
        realism: Realism | None = None,
        robot_seed: int = 0,
        period: float | None = None,
        tag_window: bool = False,
    ) -> None:
        realism = Realism() if realism is None else realism
        robot = robot_sensing(physics.model)  # robot data: drum radius, sensors' spec
        realism = for_robot(realism, robot) if robot is not None else realism
        if math.isnan(realism.tension.bias_std):
            raise ModelError(f"{physics.source} has no tension-sensor data; set bias_std")
        self.physics, self.nominal, self.realism = physics, nominal, realism
        # whether the physics' sensors read other than its straight cables' pull (asked once)
        self._sensed_apart = hasattr(type(physics), "sensed_tensions")
        noise = realism.tension.noise_std
        self.tension = TensionSensors(
            physics.n_cables,
            tension_noise_std if math.isnan(noise) else noise,
            realism.tension,
            np.random.default_rng(noise_seed),  # the run seed's own stream, as before realism
            robot_rng(robot_seed, "tension"),
        )
        self.encoders = Encoders(physics, nominal.geometry, realism.winch, home_encoders)
        self.camera: OnboardCamera | None = None
        if camera:
            if nominal.intrinsics is None:
                raise SimulationError(f"{physics.source} has no camera; run with the camera off")
            self.camera = OnboardCamera(
                physics,
                nominal.intrinsics,
                nominal.tag_size,
                realism.camera,
                robot_rng(robot_seed, "camera"),
                run_rng(noise_seed, "camera"),
                period=period,
                tag_window=tag_window,
                optics=realism.optics,
            )

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self.camera is not None:
            self.camera.close()
            self.camera = None

    @property
    def encoder_lengths(self) -> np.ndarray:
        """What the winch encoders read now (m,) [m]."""
        return self.encoders.read()

    def home(self, T_base_platform: np.ndarray) -> None:
        """Home the encoders at a known pose (the paper's "initial pose is known")."""
        self.encoders.home(T_base_platform, self._sensed())  # the tensions the sensors see

    def _sensed(self) -> np.ndarray:
        """True tensions where the sensors sit (heavy cables: that end of the catenary)."""
        p = self.physics
        if self._sensed_apart:
            return cast(_SensedTensions, p).sensed_tensions
        return p.tensions

    def render(self) -> np.ndarray:
        """The onboard camera's current frame, (H, W, 3) RGB uint8."""
        if self.camera is None:
            raise SimulationError("these sensors were built with camera=False; pass camera=True")
        return self.camera.render()

    def read(self, command: Command | None = None, render: bool | None = None) -> Measurement:
        """Read every sensor now.

        Args:
            command: the last command sent to the winches (carried in the measurement).
            render: render the camera and detect the tag; ``None`` does so when the camera is on.

        Returns:
            A frozen :class:`Measurement` (readings carry this run's seeded noise).
        """
        render = self.camera is not None if render is None else render
        tensions, clipped = self.tension.read(self._sensed())
        image = tag = None
        if render:
            if self.camera is None:
                raise SimulationError("these sensors were built with camera=False")
            image, tag = self.camera.read()
        return Measurement(
            time=self.physics.time,
            cable_lengths=self.encoder_lengths,
            tensions=tensions,
            command=command,
            image=image,
            tag=tag,
            tensions_clipped=clipped,
        )
