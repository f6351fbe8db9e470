"""The twin assembled: a :class:`Physics` core and the :class:`Sensors` that read it.

:func:`build_robot` makes the two from a model file and the robot's calibration errors; the
:class:`Twin` keeps them together for interactive use (the demo, notebooks, tests):

>>> with Twin(deviations=DeviationSpec(exit_point_std=0.005, seed=1), noise_seed=7) as twin:
...     twin.reset(T_base_platform)          # all cables taut, settled, encoders homed
...     twin.advance(0.04, cable_rates)      # winches integrate l̇ while physics steps
...     m = twin.sense()                     # encoders, noisy tensions, image, tag
...     truth = twin.physics.T_base_platform
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt

from cdpr_twin import resources
from cdpr_twin.math.se3 import matrix_from_quat_wxyz, transform
from cdpr_twin.robot.deviations import DeviationSpec, TruthDeviations
from cdpr_twin.robot.realism import CableRealism, DriveRealism, PulleyRealism, WinchRealism
from cdpr_twin.robot.schema import MAX_TIMESTEP, MIN_TIMESTEP
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim.model import (
    TAG_BODY,
    ModelError,
    NominalError,
    SimulationError,
    actuator_name,
    add_payload,
    build_model,
    cable_count,
    numeric,
    read_geometry,
)
from cdpr_twin.sim.physics import Physics
from cdpr_twin.sim.sensors import NominalRobot, Sensors
from cdpr_twin.types import Command, Measurement


def _truth(name: str, doc: str) -> property:
    """A read-only view of one of the physics' ground-truth getters."""
    return property(lambda self: getattr(self.physics, name), doc=doc)


def _nominal_robot(model: mujoco.MjModel) -> NominalRobot:
    tag = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, TAG_BODY)
    T_base_tag = None
    if tag >= 0 and model.body_parentid[tag] == 0:
        T_base_tag = transform(matrix_from_quat_wxyz(model.body_quat[tag]), model.body_pos[tag])
    has_cam = cam_mod.has_camera(model)
    tag_size = 0.0
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "tag_size") >= 0:
        tag_size = float(numeric(model, "tag_size")[0])
    geometry = read_geometry(model)
    winches = [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, actuator_name(i))
        for i in range(geometry.n_cables)
    ]
    rates = None if min(winches) < 0 else tuple(model.actuator_ctrlrange[winches].T.copy())
    return NominalRobot(
        geometry=geometry,
        intrinsics=cam_mod.intrinsics(model) if has_cam else None,
        tag_size=tag_size,
        T_base_tag=T_base_tag,
        rate_range=rates,
    )


SAME_ROBOT = 0.1
"""A nominal description whose exit points lie farther from the model's than this share of the
frame's span describes another robot (a builder's tolerances and a calibration's errors are
millimetres to centimetres: ACROBOT's 12 mm is 1 % of its 1.2 m)."""


def nominal_from_description(path: str | Path, model_nominal: NominalRobot) -> NominalRobot:
    """What the software believes when told a robot description (e.g. a calibrated one).

    Geometry, camera mount, tag pose and, when it has a calibration's ``drum_radius_scale``, the
    drum radii (× ``drum_radius_m``) come from the description; the camera intrinsics, tag size
    and the carried mass (platform and payload) stay the model's.

    Raises:
        ModelError: the description is invalid or describes another robot (another cable
            count, or an exit point beyond :data:`SAME_ROBOT` of the frame's span).
    """
    from cdpr_twin.math.workspace import geometry_of
    from cdpr_twin.robot.description import RobotError, load_robot

    try:
        r = load_robot(path)
    except RobotError as exc:
        raise NominalError(str(exc)) from None
    geom, known = geometry_of(r), model_nominal.geometry
    if geom.n_cables != known.n_cables:
        raise NominalError(
            f"{path}: {geom.n_cables} cables, but the model has "
            f"{known.n_cables}; give the same robot's description"
        )
    span = float(np.ptp(known.a_base, axis=0).max())
    off = np.linalg.norm(geom.a_base - known.a_base, axis=1)
    if off.max() > SAME_ROBOT * span:
        i = int(np.argmax(off))
        raise NominalError(
            f"{path}: exit point {i + 1} is {off[i]:.3g} m from the model's, more than "
            f"{SAME_ROBOT:.0%} of its {span:.3g} m span: a description of another robot; give "
            "the same robot's description (e.g. `cdpr-twin calibrate`'s calibrated_robot.toml)"
        )
    # what is carried (platform and payload) is known, not calibrated
    geom = replace(geom, mass=known.mass, com_platform=known.com_platform)
    if r.camera is not None:
        R = matrix_from_quat_wxyz(r.camera.quat_wxyz) @ cam_mod.R_MJCAM_CV
        geom = replace(geom, T_platform_cam=transform(R, r.camera.position))
    T_base_tag = model_nominal.T_base_tag
    if r.tag is not None:
        T_base_tag = transform(matrix_from_quat_wxyz(r.tag.quat_wxyz), r.tag.position)
    radii = None if r.drum_radius_scale is None else r.drum_radius * r.drum_radius_scale
    return replace(model_nominal, geometry=geom, T_base_tag=T_base_tag, drum_radii=radii)


def _set_timestep(model: mujoco.MjModel, timestep: float | None) -> None:
    """Set the physics step [s] (``None``: keep the model file's), within stiff cables' range."""
    if timestep is None:
        return
    if not (np.isfinite(timestep) and MIN_TIMESTEP <= timestep <= MAX_TIMESTEP):
        raise ValueError(
            f"timestep must be in [{MIN_TIMESTEP:g}, {MAX_TIMESTEP:g}] s (stiff cables; a smaller "
            f"one takes hours per simulated second), got {timestep}"
        )
    model.opt.timestep = float(timestep)


def nominal_robot(
    model_path: str | Path | None = None,
    nominal_path: str | Path | None = None,
    payload: tuple[float, npt.ArrayLike] = (0.0, np.zeros(3)),
) -> NominalRobot:
    """What the robot's software believes (as :func:`build_robot` gives it), without a twin.

    Enough to check a task against the nominal robot (a campaign's runs, before any starts).

    Raises:
        ModelError: when the model file is missing, malformed or not a cable robot.
    """
    return _nominal(model_path, nominal_path, payload)[2]


def _nominal(model_path, nominal_path, payload) -> tuple[Path, object, NominalRobot]:
    try:
        path = resources.robot_model(model_path)
    except resources.ResourceError as exc:
        raise ModelError(str(exc)) from None
    nominal_model = build_model(path)
    add_payload(nominal_model, payload[0], np.asarray(payload[1], dtype=float), str(path))
    nominal = _nominal_robot(nominal_model)
    if nominal_path is not None:
        nominal = nominal_from_description(nominal_path, nominal)
    return path, nominal_model, nominal


@dataclass(frozen=True)
class BuiltRobot:
    """A simulated robot and what its software believes of it (:func:`build_robot`).

    Attributes:
        physics: the true robot, simulated (its calibration errors in the model).
        nominal: what the estimators and controllers believe (geometry, camera, tag).
        deviations: the calibration errors the true robot was built with.
    """

    physics: Physics
    nominal: NominalRobot
    deviations: TruthDeviations


def build_robot(
    model_path: str | Path | None = None,
    deviations: DeviationSpec | TruthDeviations | None = None,
    timestep: float | None = None,
    align_every: int = 10,
    winch: WinchRealism | None = None,
    occluder: bool = False,
    nominal_path: str | Path | None = None,
    payload: tuple[float, npt.ArrayLike] = (0.0, np.zeros(3)),
    drive: DriveRealism | None = None,
    cable: CableRealism | None = None,
    pulley: PulleyRealism | None = None,
) -> BuiltRobot:
    """The simulated robot (with its calibration errors) and what its software believes.

    Args:
        model_path: MJCF scene, or a shipped robot's name (``None``: ``acrobot``).
        deviations: a :class:`DeviationSpec` (drawn with its seed for the model's cable count),
            concrete :class:`TruthDeviations`, or ``None`` for the nominal robot.
        timestep: physics step [s]; ``None`` keeps the model file's.
        align_every: physics steps between swivel/stiffness refreshes.
        winch: the winches' servo imperfections (default: none); per-robot draws use the
            deviations' seed.
        occluder: give the true scene the sheet of ``tag_occlusion`` events.
        nominal_path: a robot description the software believes instead of the model file
            (:func:`nominal_from_description`).
        payload: (mass [kg], (3,) centre of mass in F_p [m]) fixed to the platform, on the
            robot and in what its software believes (the operator knows the load).
        drive: the drums', gearboxes' and motors' imperfections (default: none).
        cable: the cables as ropes (default: the paper's elastic cables); per-robot draws use
            the deviations' seed.
        pulley: the pulleys as mechanisms and as built (default: the paper's pulleys).

    Raises:
        ModelError: when the model file is missing, malformed or not a cable robot.
        ValueError: for a bad timestep or refresh interval.
    """
    path, nominal_model, nominal = _nominal(model_path, nominal_path, payload)
    robot_seed = deviations.seed if isinstance(deviations, DeviationSpec) else 0
    n = cable_count(nominal_model)
    if isinstance(deviations, DeviationSpec):
        deviations = deviations.draw(n)
    deviations = deviations if deviations is not None else TruthDeviations.zero(n)
    model = build_model(path, deviations, occluder)
    add_payload(model, payload[0], np.asarray(payload[1], dtype=float), str(path))
    _set_timestep(model, timestep)
    source = str(path)
    cable = CableRealism() if cable is None else cable
    pulley = PulleyRealism() if pulley is None else pulley
    sag = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "cable_sag") >= 0
    ropes = cable != CableRealism() or pulley != PulleyRealism()
    if ropes and sag:
        raise ModelError(
            f"{path}: realism.cable/realism.pulley: ropes are not modelled on sagging cables; "
            "turn the robot's sag off or use the acrobot profile"
        )
    physics: Physics
    if ropes:
        from cdpr_twin.sim.rope import RopePhysics  # the cables and pulleys as they are

        physics = RopePhysics(
            model, align_every, source, winch, robot_seed, drive, cable=cable, pulley=pulley
        )
    elif sag:
        from cdpr_twin.sim.sag import SaggingPhysics  # heavy cables (robot.toml: sag = true)

        rho = float(numeric(model, "cable_linear_density")[0])
        physics = SaggingPhysics(
            model, align_every, source, winch, robot_seed, drive, linear_density=rho
        )
    else:
        physics = Physics(model, align_every, source, winch, robot_seed, drive)
    if nominal.drum_radii is not None:  # its drives and encoders, set as it believes
        try:
            physics.set_drum_radii(nominal.drum_radii)
        except ValueError as exc:  # the description's drum_radius_m is not the robot's
            raise NominalError(f"{nominal_path}: [winches] drum_radius_m × scale: {exc}") from None
    return BuiltRobot(physics, nominal, deviations)


class Twin:
    """The simulated robot with its sensors.

    Args:
        model_path: MJCF scene, or a shipped robot's name (default: ``acrobot``).
        deviations: the robot's calibration errors (see :func:`build_robot`).
        tension_noise_std: std of the tension-sensor noise [N]; 0 switches it off.
        noise_seed: seed of this run's sensor noise.
        camera: render the onboard camera and detect the tag in :meth:`sense`.
        align_every: physics steps between refreshes of the swivel yaws and cable stiffnesses.
        tau_min: lowest tension of the distribution used by :meth:`reset` [N] (default: the
            model's ``cable_tension_range``, else 2 N).
        tau_max: highest tension of that distribution [N] (default: likewise, else 75 N).
        timestep: physics step [s]; ``None`` keeps the model file's.
        home_encoders: home the encoders at :meth:`reset` (see :class:`Sensors`).
        robot: a shipped robot's name (``Twin(robot="acrobot")``), instead of ``model_path``.

    Raises:
        ModelError: when the model file is missing, malformed or not a cable robot, or the
            robot is not shipped.
        ValueError: when both ``model_path`` and ``robot`` are given.
    """

    def __init__(
        self,
        model_path: str | Path | None = None,
        deviations: DeviationSpec | TruthDeviations | None = None,
        tension_noise_std: float = 0.24,
        noise_seed: int = 0,
        camera: bool = True,
        align_every: int = 10,
        tau_min: float | None = None,
        tau_max: float | None = None,
        timestep: float | None = None,
        home_encoders: bool = True,
        robot: str | None = None,
    ) -> None:
        if model_path is not None and robot is not None:
            raise ValueError("give either model_path or robot (a shipped robot's name), not both")
        model_path = robot if robot is not None else model_path
        if not (np.isfinite(tension_noise_std) and tension_noise_std >= 0):
            raise ValueError(f"tension_noise_std must be ≥ 0 N, got {tension_noise_std}")
        built = build_robot(model_path, deviations, timestep, align_every)
        self.physics, self.nominal, self.deviations = built.physics, built.nominal, built.deviations
        self.model_path = Path(self.physics.source)
        g = self.physics.geometry  # None: the model's tension range (cable_tension_range)
        self.tau_min = g.tension_min if tau_min is None else float(tau_min)
        self.tau_max = g.tension_max if tau_max is None else float(tau_max)
        self._closed = False
        self.sensors = Sensors(
            self.physics, self.nominal, tension_noise_std, noise_seed, camera, home_encoders
        )

    model = _truth("model", "The simulated robot's ``MjModel``.")
    data = _truth("data", "The simulated robot's ``MjData``.")
    T_base_platform = _truth("T_base_platform", "Ground-truth platform pose (4, 4).")
    tensions = _truth("tensions", "True cable tensions (m,) [N].")
    cable_lengths = _truth("cable_lengths", "True stretched cable lengths (m,) [m].")
    rest_lengths = _truth("rest_lengths", "Unstretched lengths paid out (m,) [m].")
    T_cam_tag = _truth("T_cam_tag", "Ground-truth tag pose in the camera frame (4, 4).")
    timestep = _truth("timestep", "Physics step [s].")
    settle_error = _truth("settle_error", "Pose error after the last reset's settle [m, rad].")

    def close(self) -> None:
        """Free the renderer's GL context; the twin can no longer step or sense."""
        self.sensors.close()
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:
            raise SimulationError(
                "this Twin is closed; build a new one (or use it in a with block)"
            )

    def __enter__(self) -> Twin:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def nominal_geometry(self):
        """The nominal geometry (what estimators and controllers believe)."""
        return self.nominal.geometry

    @property
    def true_geometry(self):
        """The simulated robot's geometry, calibration errors included."""
        return self.physics.geometry

    def reset(self, T_base_platform: np.ndarray, settle_time: float = 0.3) -> None:
        """Settle the robot at a pose with all cables taut and home the encoders there."""
        self._check_open()
        self.physics.reset(T_base_platform, settle_time, self.tau_min, self.tau_max)
        self.sensors.home(T_base_platform)

    def advance(self, duration: float, cable_rates: np.ndarray) -> None:
        """Run the winches at constant rates while physics steps (see :meth:`Physics.advance`)."""
        self._check_open()
        self.physics.advance(duration, cable_rates)

    def sense(self, command: Command | None = None, render: bool | None = None) -> Measurement:
        """Read every sensor (see :meth:`Sensors.read`)."""
        self._check_open()
        return self.sensors.read(command, render)

    def place(self, T_base_platform: np.ndarray) -> None:
        """Put the platform at a pose kinematically (see :meth:`Physics.place`)."""
        self.physics.place(T_base_platform)

    def render(self) -> np.ndarray:
        """The onboard camera's current frame, (H, W, 3) RGB uint8."""
        return self.sensors.render()


__all__ = ["Twin", "build_robot", "cable_count"]
