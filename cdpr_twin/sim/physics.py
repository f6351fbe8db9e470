"""The thin physics core: winches, elastic cables through kinematic swivel pulleys, stepping.

Physics (docs/concepts). Each cable is a spatial tendon entry site → sheave (cylinder wrap) → B_i.
Its winch actuator carries the unstretched length l0_i as activation state (``dyntype=
integrator``: MuJoCo integrates ctrl, the rate of :mod:`~cdpr_twin.sim.winch`) and pulls with

    τ_i = (E·S / l0_i) · (L_i − l0_i) + c_i · L̇_i,   clamped to τ_i ≥ 0 (a cable never pushes),

where L_i is the tendon length less the constant entry segment (A_i → wrap → B_i, the paper's
l_f of eq. 15) and c_i = η·E·S/l0_i. The stiffness E·S/l0_i (zero for a broken cable) and the
swivel yaw φ_i (eq. 20, ideal swivels as mocap bodies) are refreshed every ``align_every`` steps.

Like dm_control's ``Physics`` it owns ``MjModel``/``MjData`` and answers named ground-truth
questions (``T_base_platform``…); step hooks (events, the fault monitor) act between steps.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from cdpr_twin.math import se3
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import cable_lengths, rest_lengths
from cdpr_twin.math.statics import tension_distribution
from cdpr_twin.options import OptionError
from cdpr_twin.robot.description import DRUM_SCALE_TOLERANCE as DRUM_TOL
from cdpr_twin.robot.realism import DriveRealism, WinchRealism, robot_rng
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim import winch as winch_mod
from cdpr_twin.sim.drive import Drums
from cdpr_twin.sim.events import StepHook, fire_due
from cdpr_twin.sim.model import (
    PLATFORM_BODY,
    ModelError,
    SimulationError,
    actuator_name,
    anchor_site,
    as_slice,
    cable_count,
    has_numeric,
    numeric,
    read_geometry,
    static_site_pose,
    swivel_body,
)
from cdpr_twin.sim.monitor import divergence
from cdpr_twin.sim.occluder import occluder_of
from cdpr_twin.sim.rope_kernel import jit
from cdpr_twin.sim.winch import WinchServos, check_lengths, checked_rates, whole_steps

TAG_SITE = "tag_center"


@jit
def set_swivels_and_stiffness(
    yaw: np.ndarray,
    mocap_quat: np.ndarray,
    mocap: np.ndarray,
    l0: np.ndarray,
    es: np.ndarray,
    enabled: np.ndarray,
    gain: np.ndarray,
    bias: np.ndarray,
    bias_unit: np.ndarray,
) -> None:
    """Turn each swivel to its yaw and write its cable's stiffness k = E·S/l0, in place.

    Compiled: one call for the dozen NumPy calls on (m,) arrays it replaces (twice a control
    tick), with the same arithmetic, so the same bits.

    Args:
        yaw: (m,) each swivel's yaw φ_i about its base z axis [rad] (eq. 20).
        mocap_quat: (k, 4) MuJoCo's mocap quaternions [w, x, y, z]; row ``mocap[i]`` is set.
        mocap: (m,) int, each swivel's mocap row.
        l0: (m,) rest lengths [m] (0 before reset: no stiffness).
        es: (m,) axial stiffnesses E·S [N].
        enabled: (m,) bool, False for a cut cable (no stiffness).
        gain: (m, ≥1) the actuators' gain parameters; column 0 gets k [N/m].
        bias: (m, ≥3) the actuators' bias parameters; columns 0–2 get k·``bias_unit``.
        bias_unit: (3,) the bias per unit stiffness [m, 1, s].
    """
    for i in range(l0.size):
        half = 0.5 * yaw[i]
        quat = mocap_quat[mocap[i]]
        quat[0], quat[1], quat[2], quat[3] = math.cos(half), 0.0, 0.0, math.sin(half)
        k = es[i] / l0[i] if l0[i] > 0 and enabled[i] else 0.0
        gain[i, 0] = k
        for j in range(3):
            bias[i, j] = k * bias_unit[j]


class Physics:
    """The simulated robot's mechanics and its ground truth.

    Args:
        model: a compiled cable-robot model (:func:`cdpr_twin.sim.build_model`).
        align_every: physics steps between refreshes of the swivel yaws and cable stiffnesses.
        source: where the model came from, for error messages.
        winch: the winches' servo imperfections (default: they follow commands instantly).
        robot_seed: the truth seed (per-robot winch errors).
        drive: the drums', gearboxes' and motors' imperfections (default: none).

    Raises:
        ModelError: when the model is not a cable robot this core can drive.
        OptionError: naming ``realism.drive.friction_rate`` for friction on a winch without a
            velocity loop.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        align_every: int = 10,
        source: str = "model",
        winch: WinchRealism | None = None,
        robot_seed: int = 0,
        drive: DriveRealism | None = None,
    ) -> None:
        if int(align_every) < 1:
            raise ValueError(f"align_every must be ≥ 1 physics step, got {align_every}")
        self.model, self.source = model, source
        self.data = mujoco.MjData(model)
        self.n_cables = cable_count(model)
        self.cable_names = tuple(f"cable{i + 1}" for i in range(self.n_cables))
        self.geometry: CdprGeometry = read_geometry(model)
        self.align_every = int(align_every)
        self.winch = winch_mod.robot_winch(model, winch)  # the drum radius: robot data
        self.drive = DriveRealism() if drive is None else drive
        self._servos = WinchServos(self.winch, self.n_cables, self.drive.friction_rate)
        if self.drive.friction_rate > 0 and math.isinf(self.winch.bandwidth_hz):
            raise OptionError(
                "realism.drive.friction_rate",
                "needs a velocity loop of finite gain: set [realism.winch] bandwidth_hz",
            )
        self._check_winding(model)
        self._drums: Drums | None = None  # (set_drum_radii builds them when the drive has any)
        rng = robot_rng(robot_seed, "winch")  # per robot; the encoders read the same radii
        self.drum_radius_true = winch_mod.draw_drum_radii(self.winch, rng, self.n_cables)
        self.set_drum_radii(np.full(self.n_cables, self.winch.drum_radius))  # until told
        self._hooks: list[StepHook] = []
        self.cable_enabled = np.ones(self.n_cables, dtype=bool)
        self._running: np.ndarray | None = None  # (m,) 0 for a stalled winch; None: none is
        self._index(model)
        # views into MjData's buffers, which live as long as it does (the actuators' ids are
        # contiguous: _index refuses others), read each tick without a look-up
        d, q, v = self.data, self._qpos, self._dof
        self._l0, self._force = d.act[self._actuators], d.actuator_force[self._actuators]
        self._pose, self._twist = d.qpos[q : q + 7], d.qvel[v : v + 6]
        self._entry = float(numeric(model, "cable_entry_height")[0])
        self._damping_time = float(numeric(model, "cable_damping_time")[0])
        # force = k·l0 + k·h − k·L − η·k·L̇: the bias per unit stiffness
        self._bias_unit = np.array([self._entry, -1.0, -self._damping_time])
        self._es = self.geometry.es.copy()
        self._a = self.geometry.a_base.copy()
        self.was_reset = False
        self.settle_error: tuple[float, float] = (math.nan, math.nan)

    def _index(self, m: mujoco.MjModel) -> None:
        """Ids of the parts the core drives (slices where contiguous, so writes are views)."""
        n, name2id, obj = self.n_cables, mujoco.mj_name2id, mujoco.mjtObj
        self._platform = name2id(m, obj.mjOBJ_BODY, PLATFORM_BODY)
        if self._platform < 0 or m.body_jntadr[self._platform] < 0:
            raise ModelError(f"{self.source}: needs a free-floating body named {PLATFORM_BODY!r}")
        self._qpos = m.jnt_qposadr[m.body_jntadr[self._platform]]
        self._dof = m.jnt_dofadr[m.body_jntadr[self._platform]]
        anchors = [name2id(m, obj.mjOBJ_SITE, anchor_site(i)) for i in range(n)]
        mocap = [m.body_mocapid[name2id(m, obj.mjOBJ_BODY, swivel_body(i))] for i in range(n)]
        actuators = np.array([name2id(m, obj.mjOBJ_ACTUATOR, actuator_name(i)) for i in range(n)])
        if min(mocap) < 0:
            raise ModelError(f"{self.source}: the pulley swivel bodies must be mocap bodies")
        self._tendons = m.actuator_trnid[actuators, 0]
        self._act_range = m.actuator_actrange[actuators].copy()
        self._anchors, self._mocap = as_slice(anchors), as_slice(mocap)
        self._mocap_ids = np.array(mocap)
        self._actuator_ids = actuators
        self._actuators = as_slice(actuators)
        self._gain = m.actuator_gainprm[self._actuators]  # views when the ids are contiguous
        self._bias = m.actuator_biasprm[self._actuators]
        shared = np.shares_memory(self._gain, m.actuator_gainprm)
        if not (shared and np.shares_memory(self._bias, m.actuator_biasprm)):
            raise ModelError(f"{self.source}: the winch actuators must be declared together")
        self.rate_range = self._ctrl_lo, self._ctrl_hi = tuple(m.actuator_ctrlrange[actuators].T)
        self._tag_site = name2id(m, obj.mjOBJ_SITE, TAG_SITE)
        self._cam = cam_mod.camera_id(m) if cam_mod.has_camera(m) else -1
        self._occluder = occluder_of(m, self.data, lambda: self.T_base_tag)

    # ------------------------------------------------------------------ ground truth
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
        q = self._pose
        return se3.transform(se3.matrix_from_quat_wxyz(q[3:]), q[:3])

    @property
    def rest_lengths(self) -> np.ndarray:
        """Unstretched lengths l0 paid out by the winches. (m,) [m]."""
        return self._l0.copy()

    @property
    def cable_lengths(self) -> np.ndarray:
        """True stretched cable lengths from A_i over the sheave to B_i (MuJoCo). (m,) [m]."""
        return self.data.ten_length[self._tendons] - self._entry

    @property
    def taut(self) -> np.ndarray:
        """(m,) each cable taut: MuJoCo's straight cable pulls (a heavy one may hang: sag.py)."""
        # tension −f > 0 is f < 0: one comparison, whatever a subclass's tensions add
        return self._force < 0.0

    @property
    def tensions(self) -> np.ndarray:
        """True cable tensions (m,) [N]."""
        return 0.0 - self._force  # 0.0 -: no "-0.0" when slack

    @property
    def winch_rates(self) -> np.ndarray:
        """The winches' actual rates dl0/dt now (m,) [m/s] (the commanded ones if ideal)."""
        return self._servos.rate.copy()

    @property
    def platform_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Views (do not write) of [x, y, z, qw, qx, qy, qz] and [v (world), ω (platform)]."""
        return self._pose, self._twist

    @property
    def has_camera(self) -> bool:
        """Whether the robot carries the onboard camera."""
        return self._cam >= 0

    @property
    def has_tag(self) -> bool:
        """Whether the scene has a tag (a site ``tag_center`` on a static body)."""
        return self._tag_site >= 0

    @property
    def T_base_cam(self) -> np.ndarray:
        """Ground-truth OpenCV camera pose (4, 4)."""
        if self._cam < 0:
            raise ModelError(f"{self.source} has no camera {cam_mod.CAMERA_NAME!r}")
        return cam_mod.T_world_cam(self.data, self._cam)

    @property
    def T_base_tag(self) -> np.ndarray:
        """Ground-truth tag pose (pupil-apriltags frame) (4, 4), from the (static) model."""
        if self._tag_site < 0:
            raise ModelError(f"{self.source} has no site {TAG_SITE!r}; use scene.xml")
        return static_site_pose(self.model, self._tag_site, self.source)

    @property
    def T_cam_tag(self) -> np.ndarray:
        """Ground-truth tag pose in the camera frame (4, 4)."""
        return se3.inverse(self.T_base_cam) @ self.T_base_tag

    @property
    def platform_half_size(self) -> np.ndarray:
        """Half-sizes of the platform box geom (3,) [m]."""
        geom = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, "platform_box")
        return self.model.geom_size[geom].copy()

    # ------------------------------------------------------------------ actuation
    def add_hook(self, hook: StepHook) -> None:
        """Let ``hook`` act between physics steps (stepping stops at its times)."""
        self._hooks.append(hook)

    def _check_winding(self, model: mujoco.MjModel) -> None:
        """Refuse a winding compliance that would shrink a drum by 10 % at the tension ceiling.

        Raises:
            OptionError: naming ``realism.drive.winding_compliance``.
        """
        kappa = self.drive.winding_compliance
        if not kappa or not has_numeric(model, "cable_tension_range"):
            return
        tau_max = float(numeric(model, "cable_tension_range")[1])
        if kappa * tau_max >= 0.1:
            raise OptionError(
                "realism.drive.winding_compliance",
                f"{kappa:g} /N shrinks the drum by {100 * kappa * tau_max:.0f} % at this "
                f"robot's {tau_max:g} N ceiling (measured: 0.3–1.2 %); keep it below "
                f"{0.1 / tau_max:.3g} /N",
            )

    def set_drum_radii(self, radii: np.ndarray) -> None:
        """Set the drives and encoders to these drum radii (m,) [m] (the software's belief)."""
        radii, r, n = np.array(radii, dtype=float), self.winch.drum_radius, self.n_cables
        if radii.shape != (n,) or not np.all(abs(radii / r - 1) <= DRUM_TOL):  # NaN fails too
            raise ValueError(f"drum radii: {n} within {100 * DRUM_TOL:g} % of {r} m: {radii}")
        self.drum_radius_set, self._drum_ratio = radii, self.drum_radius_true / radii  # cable/cmd
        if self.drive.drums:
            self._drums = Drums(self.drive, self.drum_radius_true, radii)
        self.drums_as_set = self._drums is None and np.array_equal(radii, self.drum_radius_true)
        """Whether each drum pays out exactly its command: true radii as set, no drum model."""

    def clear_hooks(self) -> None:
        """Drop every hook: they hold this physics, a cycle that kept a closed run's model alive."""
        self._hooks.clear()

    def disable_cable(self, i: int) -> None:
        """Cut cable i (from 0): its force is zero from now on, across every refresh."""
        if not 0 <= i < self.n_cables:
            raise ValueError(f"cable index {i} out of range 0…{self.n_cables - 1}")
        self.cable_enabled[i] = False
        self.refresh()
        # and now, not only from the next step: a reading at this instant sees no force
        self.data.actuator_force[self._actuator_ids[i]] = 0.0

    def stall_winch(self, i: int, stalled: bool = True) -> None:
        """Winch i (from 0) stops turning whatever it is commanded (or follows again)."""
        running = np.ones(self.n_cables) if self._running is None else self._running
        running[i] = 0.0 if stalled else 1.0
        self._running = None if running.all() else running
        self.data.ctrl[self._actuator_ids[i]] *= running[i]

    def occlude_tag(self, coverage: float) -> None:
        """Slide the sheet over ``coverage`` of the tag's code (0: park it; needs the sheet)."""
        if self._occluder is None:
            raise SimulationError(f"{self.source} was built without the tag occluder")
        self._occluder.cover(coverage)
        mujoco.mj_kinematics(self.model, self.data)  # the next frame sees it

    def refresh(self) -> None:
        """Point each swivel at its B_i (eq. 20) and set the cable stiffness E·S/l0.

        Called every ``align_every`` physics steps: the hot path of the core (one compiled
        call writes the swivels' quaternions and the actuators' gains and biases in place).
        """
        d = self.data
        lvec = d.site_xpos[self._anchors] - self._a
        # (NumPy's arctan2, not the compiled libm one: they differ in the last bit)
        yaw = np.arctan2(lvec[:, 1], lvec[:, 0])
        set_swivels_and_stiffness(
            yaw,
            d.mocap_quat,
            self._mocap_ids,
            self._l0,
            self._es,
            self.cable_enabled,
            self._gain,
            self._bias,
            self._bias_unit,
        )

    def step(self, n: int) -> None:
        """Advance n physics steps, refreshing every ``align_every`` and firing due hooks.

        Raises:
            SimulationError: when the simulation diverges.
        """
        dt, model, data, hooks = self.timestep, self.model, self.data, self._hooks
        while n > 0:
            chunk = min(n, self.align_every)
            chunk = fire_due(hooks, data.time, dt, chunk) if hooks else chunk
            self.refresh()
            self._drive_winches(chunk * dt)
            mujoco.mj_step(model, data, nstep=chunk)
            n -= chunk
        self._check_state()

    def _drive_winches(self, h: float) -> None:
        """Set the winches' rates for the next ``h`` seconds (servo loops, drums)."""
        if self._drums is not None:  # the motors turn, the drums follow, the cable winds
            self.data.ctrl[self._actuators] = self._wind(self._drums, h)
        elif not self._servos.ideal:  # the chunk's exact mean rate: l0 exact at its end
            rate = self._servos.run(h)  # the drum's, in command units
            self.data.ctrl[self._actuators] = self._stalled(rate * self._drum_ratio)

    def _drum_loads(self) -> tuple[np.ndarray, np.ndarray]:
        """The cables' forces at the drums (m,) [N] and their stiffnesses from there (m,) [N/m]."""
        return self.tensions, self._es / self._l0

    def _wind(self, drums: Drums, h: float) -> np.ndarray:
        """The rates that pay out, over ``h`` seconds, what the drums wind (m,) [m/s]."""
        motor_rate = self._servos.command if self._servos.ideal else self._servos.run(h)
        tensions, stiffness = self._drum_loads()
        return drums.advance(self._stalled(motor_rate) * h, tensions, stiffness) / h

    def rest_lengths_at(self, T_base_platform: np.ndarray) -> np.ndarray:
        """The rest lengths that hold the true robot at a pose (m,) [m].

        Under the true geometry's minimum-norm tension distribution within the model's
        ``cable_tension_range`` (what :meth:`reset` winds to by default).

        Raises:
            InfeasibleTensionError: if no tension distribution holds the platform there.
        """
        g = self.geometry
        tau = tension_distribution(g, T_base_platform, *g.tension_bounds(None, None))
        return self._rest_lengths(T_base_platform, tau)

    @property
    def motor_positions(self) -> np.ndarray | None:
        """(m,) the motors' positions since reset, r_set·φ_m [m] (``None``: no drum model)."""
        return None if self._drums is None else self._drums.motor.copy()

    def _check_state(self) -> None:
        d, bad = self.data, divergence(self.data)
        if bad or not math.isfinite(np.add.reduce(d.qpos) + np.add.reduce(d.qvel)):
            raise SimulationError(
                f"the simulation diverged at t = {d.time:.4f} s (MuJoCo warnings: {bad or 'none'});"
                " lower the timestep or the commanded cable rates"
            )

    def set_winch_rates(self, rates: np.ndarray, steps: int) -> None:
        """Command winch rates for the next ``steps`` physics steps (checked against limits).

        Raises:
            ValueError: non-finite or out-of-range rates, or rates that would run a winch past
                its range within those steps (servos: the exact lengths their loops reach).
        """
        self._command(checked_rates(rates, self.n_cables, self._ctrl_lo, self._ctrl_hi), steps)

    def _command(self, rates: np.ndarray, steps: int) -> None:
        """:meth:`set_winch_rates` of rates (m,) [m/s] that :func:`checked_rates` returned."""
        paid = self._servos.paid_out(rates, steps, self.timestep) * self._drum_ratio
        # the lengths reached, read in place (the public rest_lengths copies)
        check_lengths(self._l0 + paid, self._act_range)
        self._servos.set_command(rates)
        if (
            self._servos.ideal and self._drums is None
        ):  # (× 1.0 exactly without drum errors: bit for bit as before)
            self.data.ctrl[self._actuators] = self._stalled(rates * self._drum_ratio)

    def _stalled(self, ctrl: np.ndarray) -> np.ndarray:
        return ctrl if self._running is None else ctrl * self._running

    def steps_in(self, duration: float) -> int:
        """The whole number of physics steps in ``duration`` seconds (see :func:`whole_steps`)."""
        return whole_steps(duration, self.timestep)

    def advance(self, duration: float, cable_rates: np.ndarray) -> None:
        """Run the winches at constant rates while physics steps.

        Args:
            duration: how long [s]; a whole number of physics steps.
            cable_rates: (m,) winch rates dl0/dt [m/s] (positive pays cable out).

        Raises:
            ValueError: bad rates or duration (see :meth:`set_winch_rates`, :meth:`steps_in`).
            SimulationError: before :meth:`reset`, or when the simulation diverges.
        """
        if not self.was_reset:
            raise SimulationError(
                "call reset(T_base_platform) before advance(): the winches have paid out no "
                "cable yet"
            )
        rates = checked_rates(cable_rates, self.n_cables, self._ctrl_lo, self._ctrl_hi)  # first
        n = self.steps_in(duration)
        self._command(rates, n)
        self.step(n)

    # ------------------------------------------------------------------ placing
    def place(self, T_base_platform: np.ndarray) -> None:
        """Put the platform at a pose kinematically (no dynamics, winches untouched).

        Swivels are aligned and positions, tendon lengths and Jacobians recomputed, so that
        MuJoCo's own cable geometry can be inspected at any pose. Velocities are zeroed.

        Args:
            T_base_platform: (4, 4) platform pose.
        """
        T = self.geometry.check_pose_inside(T_base_platform, "placed pose")
        d, m = self.data, self.model
        d.qpos[self._qpos : self._qpos + 3] = T[:3, 3]
        d.qpos[self._qpos + 3 : self._qpos + 7] = se3.quat_wxyz_from_matrix(T[:3, :3])
        d.qvel[:] = 0.0
        mujoco.mj_kinematics(m, d)
        self.refresh()
        mujoco.mj_forward(m, d)

    def _rest_lengths(self, T_base_platform: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The winches' rest lengths l0 that hold the tensions τ (m,) [N] at a pose. (m,) [m]."""
        return rest_lengths(cable_lengths(self.geometry, T_base_platform, "pulley"), tau, self._es)

    def reset(
        self,
        T_base_platform: np.ndarray,
        settle_time: float = 0.3,
        tau_min: float | None = None,
        tau_max: float | None = None,
    ) -> None:
        """Place the platform at a pose, all cables taut, and let it settle.

        The rest lengths come from a minimum-norm tension distribution of the *true* robot
        (τ_min ≤ τ ≤ τ_max), so the pose is a static equilibrium; the settle removes numerical
        residue only. Time restarts at 0; every cable is enabled again.

        Args:
            T_base_platform: (4, 4) requested platform pose.
            settle_time: how long to settle [s].
            tau_min: lowest tension [N] (default: the model's ``cable_tension_range``).
            tau_max: highest tension [N] (default: the model's ``cable_tension_range``).

        Raises:
            ValueError: if the pose leaves the frame.
            InfeasibleTensionError: if no tension distribution holds the platform there.
        """
        geom = self.geometry
        T = geom.check_pose_inside(T_base_platform, "reset pose")
        tau = tension_distribution(geom, T, *geom.tension_bounds(tau_min, tau_max))  # pulley
        self._start(T, settle_time, tau=tau)

    def settle_at_lengths(
        self, rest_lengths: np.ndarray, T_guess: np.ndarray, settle_time: float = 2.0
    ) -> None:
        """Wind the cables to these rest lengths and let the platform settle where they hold it.

        What a robot whose drums were each zeroed on its own does: the platform is released
        near ``T_guess`` and comes to rest where the cables' elastic forces balance its weight,
        some cables perhaps slack. Time restarts at 0; every cable is enabled again.

        Args:
            rest_lengths: (m,) unstretched lengths l0 [m].
            T_guess: (4, 4) where the platform is released.
            settle_time: how long to settle [s] (the slowest mode of ACROBOT's platform decays
                by e in ≈ 0.25 s: 2 s leaves 3e-4 of the first offset).

        Raises:
            ValueError: if the pose leaves the frame or a length is not positive.
        """
        T = self.geometry.check_pose_inside(T_guess, "start pose")
        l0 = np.array(rest_lengths, dtype=float)
        if l0.shape != (self.n_cables,) or not np.all(l0 > 0):
            raise ValueError(f"rest lengths: {self.n_cables} positive lengths [m], got {l0}")
        self._start(T, settle_time, l0=l0)

    def _start(
        self,
        T: np.ndarray,
        settle: float,
        *,
        tau: np.ndarray | None = None,
        l0: np.ndarray | None = None,
    ) -> None:
        """Rest lengths at pose T, winches at rest, then settle ``settle`` seconds.

        The cables are first wound to hold the tensions τ at T (subclasses set their internal
        state there, as a robot long at rest at T); ``l0``, if given, then replaces the rest
        lengths, and the platform settles where they hold it.

        Args:
            T: (4, 4) the pose the platform is released at.
            settle: how long to settle [s].
            tau: (m,) the tensions [N] at T (default: :meth:`rest_lengths_at`'s).
            l0: (m,) the rest lengths [m] to wind instead of those holding τ.
        """
        mujoco.mj_resetData(self.model, self.data)
        self._servos.reset()  # winches at rest
        self.cable_enabled[:] = True
        self._running = None
        if tau is None:
            held = self.rest_lengths_at(T)
        else:
            held = self._rest_lengths(T, tau)
        self.data.act[self._actuators] = held if l0 is None else l0
        if self._drums is not None:
            self._drums.reset()
        self.place(T)
        self.was_reset = True
        hooks, self._hooks = self._hooks, []  # no event acts while settling
        try:
            self.step(round(settle / self.timestep))
        finally:
            self._hooks = hooks
        self.settle_error = se3.pose_distance(T, self.T_base_platform)
        self.data.time = 0.0
