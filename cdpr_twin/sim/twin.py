"""The ACROBOT twin: winches, elastic cables through kinematic swivel pulleys, sensors, camera.

Physics (DESIGN §5). Each cable is a spatial tendon entry site → sheave (cylinder wrap) → B_i.
Its winch actuator carries the unstretched length l0_i as activation state (``dyntype=
integrator``: MuJoCo integrates the commanded rate exactly every step) and pulls with

    τ_i = (E·S / l0_i) · (L_i − l0_i) + c_i · L̇_i,   clamped to τ_i ≥ 0 (a cable never pushes),

where L_i is the tendon length less the constant entry segment (A_i → wrap → B_i, the paper's
l_f of eq. 15) and c_i = η·E·S/l0_i. The stiffness E·S/l0_i and the swivel yaw φ_i (eq. 20, the
ideal swivel as mocap bodies) are refreshed from Python every ``align_every`` physics steps.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from cdpr_twin import DEFAULT_SCENE
from cdpr_twin.deviations import N_CABLES, DeviationSpec, TruthDeviations
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.kinematics import cable_lengths, rest_lengths
from cdpr_twin.measurement import Measurement
from cdpr_twin.se3 import (
    inverse,
    matrix_from_quat_wxyz,
    pose_distance,
    quat_wxyz_from_matrix,
    transform,
)
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim.model import (
    PLATFORM_BODY,
    TAG_BODY,
    ModelError,
    actuator_name,
    anchor_site,
    build_model,
    numeric,
    read_geometry,
    swivel_body,
)
from cdpr_twin.statics import tension_distribution
from cdpr_twin.vision import TagDetector

TAG_SITE = "tag_center"
_BAD_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)


def _as_slice(ids: np.ndarray) -> slice | np.ndarray:
    """A slice when ids are consecutive (assignments through it are views), else the ids."""
    ids = np.asarray(ids)
    if ids.size and np.all(np.diff(ids) == 1):
        return slice(int(ids[0]), int(ids[-1]) + 1)
    return ids


class SimulationError(RuntimeError):
    """The simulation diverged or was asked for something it cannot do."""


class Twin:
    """The simulated ACROBOT.

    Args:
        model_path: MJCF scene (default: ``models/acrobot/scene.xml``).
        deviations: the robot's calibration errors: a :class:`DeviationSpec` (drawn with its
            seed), concrete :class:`TruthDeviations`, or ``None`` for the nominal robot.
        tension_noise_std: std of the Gaussian noise on tension readings [N] (paper: 0.24 N
            accuracy); 0 switches noise off.
        noise_seed: seed of this run's sensor noise.
        camera: render the onboard camera and detect the tag in :meth:`sense`.
        align_every: physics steps between refreshes of the swivel yaws and cable stiffnesses.
        tau_min: lowest tension of the distribution used by :meth:`reset` [N].
        tau_max: highest tension of that distribution [N].
        timestep: physics step [s]; ``None`` keeps the model file's.
        home_encoders: at :meth:`reset`, zero the encoders the way a real robot is homed at a
            known pose: they then read the rest lengths the *nominal* model predicts there (with
            the measured tensions), plus whatever the winches pay out afterwards. Without
            homing they read the true rest lengths, which a deviated robot's nominal model
            cannot match even at the start.

    Raises:
        ModelError: when the model file is missing, malformed or not ACROBOT-shaped.
    """

    def __init__(
        self,
        model_path: str | Path = DEFAULT_SCENE,
        deviations: DeviationSpec | TruthDeviations | None = None,
        tension_noise_std: float = 0.24,
        noise_seed: int = 0,
        camera: bool = True,
        align_every: int = 10,
        tau_min: float = 2.0,
        tau_max: float = 75.0,
        timestep: float | None = None,
        home_encoders: bool = True,
    ) -> None:
        if not (np.isfinite(tension_noise_std) and tension_noise_std >= 0):
            raise ValueError(f"tension_noise_std must be ≥ 0 N, got {tension_noise_std}")
        if int(align_every) < 1:
            raise ValueError(f"align_every must be ≥ 1 physics step, got {align_every}")
        self.model_path = Path(model_path)
        nominal = build_model(self.model_path)
        self.nominal_geometry: CdprGeometry = read_geometry(nominal)
        tag = mujoco.mj_name2id(nominal, mujoco.mjtObj.mjOBJ_BODY, TAG_BODY)
        self.nominal_T_base_tag: np.ndarray | None = None
        """Tag pose the model file states (pupil frame), before deviations; ``None`` if none."""
        if tag >= 0 and nominal.body_parentid[tag] == 0:
            self.nominal_T_base_tag = transform(
                matrix_from_quat_wxyz(nominal.body_quat[tag]), nominal.body_pos[tag]
            )
        if isinstance(deviations, DeviationSpec):
            deviations = deviations.draw(N_CABLES)
        self.deviations = deviations if deviations is not None else TruthDeviations.zero()
        self.model = build_model(self.model_path, self.deviations)
        if timestep is not None:
            if not (np.isfinite(timestep) and 0 < timestep <= 0.002):
                raise ValueError(
                    f"timestep must be in (0, 0.002] s for stiff cables, got {timestep}"
                )
            self.model.opt.timestep = float(timestep)
        self.data = mujoco.MjData(self.model)
        self.true_geometry: CdprGeometry = read_geometry(self.model)
        self.tension_noise_std = float(tension_noise_std)
        self.align_every = int(align_every)
        self.tau_min, self.tau_max = float(tau_min), float(tau_max)
        self._rng = np.random.default_rng(noise_seed)

        m = self.model
        name2id = mujoco.mj_name2id
        self._platform = name2id(m, mujoco.mjtObj.mjOBJ_BODY, PLATFORM_BODY)
        self._qpos = m.jnt_qposadr[m.body_jntadr[self._platform]]
        self._anchors = np.array(
            [name2id(m, mujoco.mjtObj.mjOBJ_SITE, anchor_site(i)) for i in range(N_CABLES)]
        )
        self._mocap = np.array(
            [
                m.body_mocapid[name2id(m, mujoco.mjtObj.mjOBJ_BODY, swivel_body(i))]
                for i in range(N_CABLES)
            ]
        )
        self._actuators = np.array(
            [name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, actuator_name(i)) for i in range(N_CABLES)]
        )
        self._tendons = m.actuator_trnid[self._actuators, 0]
        if np.any(self._mocap < 0):
            raise ModelError(f"{self.model_path}: the pulley swivel bodies must be mocap bodies")
        self._act_range = m.actuator_actrange[self._actuators].copy()
        self._entry = float(numeric(m, "cable_entry_height")[0])
        self._damping_time = float(numeric(m, "cable_damping_time")[0])
        self._es = self.true_geometry.es.copy()
        self._a = self.true_geometry.a_base.copy()
        self._rates = np.zeros(N_CABLES)
        self._twist: np.ndarray | None = None
        self._anchors = _as_slice(self._anchors)
        self._mocap = _as_slice(self._mocap)
        self._actuators = _as_slice(self._actuators)
        self._quat_buf = np.zeros((N_CABLES, 4))
        self._gain = m.actuator_gainprm[self._actuators]  # views when the ids are contiguous
        self._bias = m.actuator_biasprm[self._actuators]
        if not (
            np.shares_memory(self._gain, m.actuator_gainprm)
            and np.shares_memory(self._bias, m.actuator_biasprm)
        ):
            raise ModelError(f"{self.model_path}: the winch actuators must be declared together")
        # force = k·l0 + k·h − k·L − η·k·L̇: the bias per unit stiffness
        self._bias_unit = np.array([self._entry, -1.0, -self._damping_time])
        self._ctrl_lo, self._ctrl_hi = m.actuator_ctrlrange[self._actuators].T.copy()
        self._tag_site = name2id(m, mujoco.mjtObj.mjOBJ_SITE, TAG_SITE)

        self._renderer: cam_mod.CameraRenderer | None = None
        self._detector: TagDetector | None = None
        if camera:
            self._renderer = cam_mod.CameraRenderer(m)
            self._detector = TagDetector(self._renderer.intrinsics, tag_size=self.tag_size)
        self._cam = cam_mod.camera_id(m)
        self.intrinsics = cam_mod.intrinsics(m)
        self.settle_error: tuple[float, float] = (math.nan, math.nan)
        self.home_encoders = bool(home_encoders)
        self._encoder_offset = np.zeros(N_CABLES)
        self._was_reset = False

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> Twin:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ state
    @property
    def timestep(self) -> float:
        """Physics step [s]."""
        return float(self.model.opt.timestep)

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.data.time)

    @property
    def T_base_platform(self) -> np.ndarray:
        """Ground-truth platform pose (4, 4)."""
        q = self.data.qpos[self._qpos : self._qpos + 7]
        return transform(matrix_from_quat_wxyz(q[3:]), q[:3])

    @property
    def rest_lengths(self) -> np.ndarray:
        """Unstretched lengths l0 paid out by the winches (the encoders' values). (m,) [m]."""
        return self.data.act[self._actuators].copy()

    @property
    def encoder_lengths(self) -> np.ndarray:
        """What the winch encoders read: rest lengths plus the homing offset. (m,) [m]."""
        return self.rest_lengths + self._encoder_offset

    @property
    def cable_lengths(self) -> np.ndarray:
        """True stretched cable lengths from A_i over the sheave to B_i (MuJoCo). (m,) [m]."""
        return self.data.ten_length[self._tendons] - self._entry

    @property
    def tensions(self) -> np.ndarray:
        """Noise-free cable tensions (m,) [N]."""
        return 0.0 - self.data.actuator_force[self._actuators]  # 0.0 -: no "-0.0" when slack

    @property
    def T_base_cam(self) -> np.ndarray:
        """Ground-truth OpenCV camera pose (4, 4)."""
        return cam_mod.T_world_cam(self.data, self._cam)

    @property
    def T_base_tag(self) -> np.ndarray:
        """Ground-truth tag pose (pupil-apriltags frame) (4, 4), from the (static) model."""
        if self._tag_site < 0:
            raise ModelError(f"{self.model_path} has no site {TAG_SITE!r}; use scene.xml")
        m = self.model
        body = m.site_bodyid[self._tag_site]
        if m.body_parentid[body] != 0 or m.body_mocapid[body] >= 0:
            raise ModelError(f"{self.model_path}: the tag must be on a static child of the world")
        T_body = transform(matrix_from_quat_wxyz(m.body_quat[body]), m.body_pos[body])
        return T_body @ transform(
            matrix_from_quat_wxyz(m.site_quat[self._tag_site]), m.site_pos[self._tag_site]
        )

    @property
    def tag_size(self) -> float:
        """Edge of the tag's black square [m] (``<numeric name="tag_size">``)."""
        return float(numeric(self.model, "tag_size")[0])

    @property
    def platform_half_size(self) -> np.ndarray:
        """Half-sizes of the platform box geom (3,) [m]."""
        geom = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, "platform_box")
        return self.model.geom_size[geom].copy()

    @property
    def T_cam_tag(self) -> np.ndarray:
        """Ground-truth tag pose in the camera frame (4, 4)."""
        return inverse(self.T_base_cam) @ self.T_base_tag

    # ------------------------------------------------------------------ physics
    def _align(self) -> None:
        """Point each swivel at its B_i (eq. 20) and set the cable stiffness E·S/l0.

        Called every ``align_every`` physics steps: the hot path of the twin (index arrays
        are slices wherever the model's ids are contiguous, so the assignments are views).
        """
        d = self.data
        lvec = d.site_xpos[self._anchors] - self._a
        half = 0.5 * np.arctan2(lvec[:, 1], lvec[:, 0])
        quat = self._quat_buf
        quat[:, 0] = np.cos(half)
        quat[:, 3] = np.sin(half)
        d.mocap_quat[self._mocap] = quat
        l0 = d.act[self._actuators]
        k = np.divide(self._es, l0, out=np.zeros(N_CABLES), where=l0 > 0)  # 0 before reset()
        self._gain[:, 0] = k
        self._bias[:, :3] = k[:, None] * self._bias_unit

    def _step(self, n: int) -> None:
        while n > 0:
            chunk = min(n, self.align_every)
            self._align()
            mujoco.mj_step(self.model, self.data, nstep=chunk)
            n -= chunk
        self._check_state()

    def _check_state(self) -> None:
        d = self.data
        bad = [mujoco.mjtWarning(w).name for w in _BAD_WARNINGS if d.warning[w].number > 0]
        if bad or not math.isfinite(d.qpos.sum() + d.qvel.sum()):
            raise SimulationError(
                f"the simulation diverged at t = {d.time:.4f} s (MuJoCo warnings: {bad or 'none'});"
                " lower the timestep or the commanded cable rates"
            )

    def place(self, T_base_platform: np.ndarray) -> None:
        """Put the platform at a pose kinematically (no dynamics, winches untouched).

        Swivels are aligned and positions, tendon lengths and Jacobians recomputed, so that
        MuJoCo's own cable geometry can be inspected at any pose. Velocities are zeroed.

        Args:
            T_base_platform: (4, 4) platform pose.
        """
        T = self.true_geometry.check_pose_inside(T_base_platform, "placed pose")
        d, m = self.data, self.model
        d.qpos[self._qpos : self._qpos + 3] = T[:3, 3]
        d.qpos[self._qpos + 3 : self._qpos + 7] = quat_wxyz_from_matrix(T[:3, :3])
        d.qvel[:] = 0.0
        mujoco.mj_kinematics(m, d)
        self._align()
        mujoco.mj_forward(m, d)

    def reset(self, T_base_platform: np.ndarray, settle_time: float = 0.3) -> None:
        """Place the platform at a pose, all cables taut, and let it settle.

        The rest lengths come from a minimum-norm tension distribution of the *true* robot
        (τ_min ≤ τ ≤ τ_max), so the pose is a static equilibrium; the settle removes numerical
        residue only. Time restarts at 0.

        Args:
            T_base_platform: (4, 4) requested platform pose.
            settle_time: how long to settle [s].

        Raises:
            ValueError: if the pose leaves the frame.
            InfeasibleTensionError: if no tension distribution holds the platform there.
        """
        geom = self.true_geometry
        T = geom.check_pose_inside(T_base_platform, "reset pose")
        tau = tension_distribution(geom, T, self.tau_min, self.tau_max, model="pulley")
        lengths = cable_lengths(geom, T, "pulley")
        l0 = rest_lengths(lengths, tau, self._es)
        mujoco.mj_resetData(self.model, self.data)
        self.data.act[self._actuators] = l0
        self._rates = np.zeros(N_CABLES)
        self._twist = None
        self.place(T)
        self._was_reset = True
        self._step(round(settle_time / self.timestep))
        self.settle_error = pose_distance(T, self.T_base_platform)
        self.data.time = 0.0
        self._encoder_offset = np.zeros(N_CABLES)
        if self.home_encoders:
            g = self.nominal_geometry
            l0_nominal = rest_lengths(cable_lengths(g, T, "pulley"), self.tensions, g.es)
            self._encoder_offset = l0_nominal - self.rest_lengths

    def advance(
        self,
        duration: float,
        cable_rates: np.ndarray,
        twist_platform: np.ndarray | None = None,
    ) -> None:
        """Run the winches at constant rates while physics steps.

        Args:
            duration: how long [s]; a whole number of physics steps.
            cable_rates: (m,) winch rates dl0/dt [m/s] (positive pays cable out).
            twist_platform: (6,) the platform twist that produced these rates, recorded in the
                next :class:`Measurement` for the control-based estimator; optional.

        Raises:
            ValueError: non-finite or out-of-range rates, a duration that is not a whole number
                of steps, or rates that would run a winch past its range.
            SimulationError: when the simulation diverges.
        """
        if not self._was_reset:
            raise SimulationError(
                "call Twin.reset(T_base_platform) before advance(): the "
                "winches have paid out no cable yet"
            )
        rates = np.array(cable_rates, dtype=float)
        if rates.shape != (N_CABLES,):
            raise ValueError(f"cable_rates must have shape ({N_CABLES},), got {rates.shape}")
        if not math.isfinite(rates.sum()):
            raise ValueError(
                f"cable_rates must be finite, got {rates.tolist()} (NaN or inf "
                "from the controller?)"
            )
        lo, hi = self._ctrl_lo, self._ctrl_hi
        if (rates < lo).any() or (rates > hi).any():
            raise ValueError(
                f"cable rates {np.round(rates, 4).tolist()} m/s exceed the winches' "
                f"range [{lo.min()}, {hi.max()}] m/s"
            )
        if twist_platform is not None:
            twist_platform = np.array(twist_platform, dtype=float)
            if twist_platform.shape != (6,) or not math.isfinite(twist_platform.sum()):
                raise ValueError(f"twist_platform must be 6 finite numbers, got {twist_platform}")
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"duration must be a finite number of seconds ≥ 0, got {duration}")
        n = round(duration / self.timestep)
        if n < 0 or not math.isclose(n * self.timestep, duration, rel_tol=1e-9, abs_tol=1e-12):
            raise ValueError(
                f"duration {duration} s is not a whole number of physics steps of {self.timestep} s"
            )
        l0_end = self.rest_lengths + rates * n * self.timestep
        if np.any(l0_end < self._act_range[:, 0]) or np.any(l0_end > self._act_range[:, 1]):
            raise ValueError(
                f"these rates would run winch lengths to {np.round(l0_end, 4)} m, "
                f"outside the winch range {self._act_range[0].tolist()} m"
            )
        self._rates = rates
        self._twist = twist_platform
        self.data.ctrl[self._actuators] = rates
        self._step(n)

    # ------------------------------------------------------------------ sensors
    def render(self) -> np.ndarray:
        """The onboard camera's current frame, (H, W, 3) RGB uint8."""
        if self._renderer is None:
            raise SimulationError("this Twin was built with camera=False; pass camera=True")
        return self._renderer.render(self.data)

    def sense(self, render: bool | None = None) -> Measurement:
        """Read every sensor now.

        Args:
            render: render the camera and detect the tag; ``None`` does so when the twin has a
                camera.

        Returns:
            A frozen :class:`Measurement` (tensions carry this run's seeded noise).
        """
        render = self._renderer is not None if render is None else render
        tensions = self.tensions
        if self.tension_noise_std > 0:
            tensions = tensions + self._rng.normal(0.0, self.tension_noise_std, N_CABLES)
        image = tag = None
        if render:
            image = self.render()
            assert self._detector is not None
            tag = self._detector.detect(image)
        return Measurement(
            time=self.time,
            cable_lengths=self.encoder_lengths,
            tensions=tensions,
            cable_rates=self._rates.copy(),
            twist_platform=None if self._twist is None else self._twist.copy(),
            T_base_platform_true=self.T_base_platform,
            image=image,
            tag=tag,
        )
