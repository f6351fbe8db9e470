"""Cables as ropes and pulleys as built: the truth beyond the paper's cable and pulley models.

:class:`RopePhysics` is :class:`~cdpr_twin.sim.physics.Physics` with the effects of
:class:`~cdpr_twin.robot.realism.CableRealism` and :class:`~cdpr_twin.robot.realism.PulleyRealism`
(magnitudes and sources: ``models/acrobot/README.md``); the estimators keep the paper's models.

**The cable.** Cable i runs from its drum to the pulley (the *drum segment*, a fixed length
l_d) and from the pulley's point A_i over the sheave to B_i (the *platform segment*, MuJoCo's
tendon less its entry segment, length L). The winch pays out l0 (``act``, as in
:class:`Physics`); the two segments share the unstretched length u_w + u_p = l0 + l_d. Each
segment is a standard linear solid (a spring k∞ in parallel with a Maxwell arm k_m, dashpot
η): with the strain ε = L/u − 1 and the dashpot's strain ε_d,

    τ = E₀·ε − E_m·ε_d,      dε_d/dt = (ε − ε_d)/t_σ,

where E₀ = ρ_i·E·S (the rope's instantaneous stiffness, ρ_i drawn per cable), E∞ = r·E₀ its
relaxed one, E_m = E₀ − E∞ and t_σ = r·t_c, t_c the retardation (creep) time. Under a constant
tension τ the strain creeps as τ/E∞ − τ(1/E∞ − 1/E₀)·exp(−t/t_c).

**The sheave.** The cable slides over the sheave only when the tensions on its sides reach
the sheave's efficiency η (bearing and bending losses, lumped): τ_low = η·τ_high, the high
side the one pulling the cable over the sheave: reeling in, the winch side, τ_p = η·τ_w;
paying out, the platform side, τ_w = η·τ_p. Between these the cable sticks (u_p fixed): a
stick-slip (Coulomb) law with no rate dependence.

**Integration.** The internal state (u_p, ε_d of each segment) is updated before every
physics step: u_p by the stick-slip law (in closed form: a quadratic per cable), ε_d by the
exact exponential of its linear ODE over one step with ε held (unconditionally stable for any
t_σ). MuJoCo then steps the platform with each cable's force linearised about that state in
the tendon's length (``gainprm``/``biasprm`` of the winch actuator): the platform segment's
stiffness E₀/u_p while the cable sticks, the two segments' in series while it slides; the
damping (``cable_damping_time`` × that stiffness, implicit in MuJoCo) acts on the strain rate.
The update runs compiled, one call per step (:mod:`cdpr_twin.sim.rope_kernel`). Without
creep or friction the two segments share one strain, and the winch's stiffness is simply
E₀/(l0 + l_d), refreshed with the swivels as in :class:`Physics`.

**The pulleys as built.** The cable's centreline wraps the sheave at r_p + d/2, the sheave's
centre sits r_p + d/2 from the swivel axis (the cable comes down the axis), offset by a
per-robot draw, and each swivel axis is tilted by a per-robot draw; the swivel turns about its
tilted axis toward B_i.

**The swivels' friction.** A swivel is a massless rotation about its axis: the cable pulls at
the groove's exit point T (x_t from the axis) toward B_i, a moment τ·x_t·ρ·sin α/ℓ about the
axis when the swivel lags B_i's azimuth by α (ρ B_i's distance from the axis, ℓ the free
span), against the bearing's Coulomb friction μ·(d/2)·τ·|û + ẑ| (the cable's load on the
bearing, û its direction out of the groove). Both scale with τ: a swivel turns only to keep
|α| ≤ α*, sin α* ≈ μ·d/(2·r·sin(θ/2)·sin θ) for a cable leaving at θ from the axis (exact:
:func:`~cdpr_twin.sim.rope_kernel.swivel_slip`), applied at each refresh. MuJoCo's swivels
stay aligned; a lagging cable is longer in its groove by ΔL ≈ x_t·ρ·α²/(2ℓ)
(:func:`~cdpr_twin.sim.rope_kernel.groove_stretch`), added to its force law.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from cdpr_twin.math.se3 import quat_wxyz_from_matrix, so3_exp
from cdpr_twin.robot.realism import (
    CableRealism,
    DriveRealism,
    PulleyRealism,
    WinchRealism,
    robot_rng,
)
from cdpr_twin.sim import rope_kernel as kernel
from cdpr_twin.sim.events import fire_due
from cdpr_twin.sim.model import ModelError, as_slice, sheave_geom, side_site
from cdpr_twin.sim.physics import Physics

_KernelArgs = tuple[
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
]
"""The nine arrays :func:`~cdpr_twin.sim.rope_kernel.update_ropes` takes before ``relax``."""


def sls_tension(
    eps: np.ndarray, eps_d: np.ndarray, es0: np.ndarray, es_m: np.ndarray
) -> np.ndarray:
    """A standard linear solid's tension τ = E₀·ε − E_m·ε_d [N].

    Args:
        eps: strains ε = L/u − 1.
        eps_d: the dashpots' strains ε_d.
        es0: instantaneous stiffness E₀ = E∞ + E_m [N].
        es_m: the Maxwell arm's stiffness E_m [N].
    """
    return es0 * eps - es_m * eps_d


def relax_dashpots(eps_d: np.ndarray, eps: np.ndarray, decay: float) -> np.ndarray:
    """Advance the dashpots' strains by one step h, in place: ε_d ← ε + (ε_d − ε)·decay.

    The exact solution of dε_d/dt = (ε − ε_d)/t_σ for ε held over the step, decay =
    exp(−h/t_σ): stable for any h/t_σ. Returns ``eps_d``.
    """
    eps_d -= eps
    eps_d *= decay
    eps_d += eps
    return eps_d


def relaxation_decay(cable: CableRealism, timestep: float) -> float:
    """exp(−h/t_σ) of the dashpots over one physics step h [s], t_σ = r·t_c (1: no creep)."""
    return math.exp(-timestep / (cable.relaxed_ratio * cable.creep_time))


def draw_rope_ratios(cable: CableRealism, robot_seed: int, n: int) -> np.ndarray:
    """One robot's rope stiffness ratios ρ_i = ρ·(1 + N(0, σ)) per cable. (n,)."""
    rng = robot_rng(robot_seed, "cable")
    return cable.rope_stiffness_ratio * (1.0 + rng.normal(0.0, cable.rope_stiffness_std, n))


def draw_pulley_geometry(pulley: PulleyRealism, robot_seed: int, n: int) -> np.ndarray:
    """One robot's swivel tilts and sheave offsets. (n, 4): [tilt x, tilt y (rad), δx, δz (m)].

    δx moves the sheave's centre along its radius through the swivel axis, δz along the swivel
    axis: both in the sheave's plane (MuJoCo's cylinder is unbounded along its axis, so an
    offset across the plane would change nothing).
    """
    rng = robot_rng(robot_seed, "pulley")
    tilt = rng.normal(0.0, pulley.swivel_tilt_std, (n, 2))
    offset = rng.normal(0.0, pulley.sheave_offset_std, (n, 2))
    return np.hstack([tilt, offset])


def apply_pulley_geometry(
    model: mujoco.MjModel, pulley: PulleyRealism, draws: np.ndarray, n: int
) -> None:
    """Move each sheave as built: wrap radius r_p + d/2, centre r_p + d/2 + δx from the axis, δz.

    Edits the compiled model in place (the tendon wrap reads ``geom_size``/``geom_pos``).
    """
    name2id, obj = mujoco.mj_name2id, mujoco.mjtObj
    for i in range(n):
        geom = name2id(model, obj.mjOBJ_GEOM, sheave_geom(i))
        side = name2id(model, obj.mjOBJ_SITE, side_site(i))
        r = float(model.geom_size[geom, 0]) + 0.5 * pulley.wrap_diameter
        model.geom_size[geom, 0] = r
        centre = np.array([r + draws[i, 2], 0.0, draws[i, 3]])
        model.geom_pos[geom] = centre
        model.site_pos[side] = centre - np.array([0.0, 0.0, 2.0 * r])


class RopePhysics(Physics):
    """:class:`Physics` with ropes for cables and pulleys as built (see the module).

    Args:
        model: as :class:`Physics` (its pulleys are moved as built here).
        *args: as :class:`Physics`.
        cable: the cables as ropes.
        pulley: the pulleys as mechanisms and as built.
        robot_seed: the truth seed (per-robot draws).
        **kwargs: as :class:`Physics`.

    Raises:
        ModelError: a sheave with friction and no drum segment (the cable has nothing to
            slide into).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        align_every: int = 10,
        source: str = "model",
        winch: WinchRealism | None = None,
        robot_seed: int = 0,
        drive: DriveRealism | None = None,
        *,
        cable: CableRealism,
        pulley: PulleyRealism,
    ) -> None:
        from cdpr_twin.sim.model import cable_count

        n = cable_count(model)
        self.pulley_draws = draw_pulley_geometry(pulley, robot_seed, n)
        apply_pulley_geometry(model, pulley, self.pulley_draws, n)
        super().__init__(model, align_every, source, winch, robot_seed, drive)
        if pulley.sheave_efficiency < 1.0 and cable.drum_segment <= 0.0:
            raise ModelError(
                "realism.pulley.sheave_efficiency: a sheave with friction needs "
                "realism.cable.drum_segment > 0 m (the cable between drum and pulley)"
            )
        if pulley.sheave_efficiency < 1.0 and not cable.strain_damping:
            raise ModelError(
                "realism.pulley.sheave_efficiency: a sheave with friction needs "
                "realism.cable.strain_damping = true (damping on L̇ would hold a paid-out cable)"
            )
        self.cable, self.pulley = cable, pulley
        # the swivels' quaternions, tilt then yaw
        self._quat_buf = np.zeros((n, 4))
        self.rope_ratio = draw_rope_ratios(cable, robot_seed, n)
        self.es0 = self.geometry.es * self.rope_ratio
        self._es = self.es0 * cable.relaxed_ratio  # the relaxed stiffness holds a rest
        self.es_m = self.es0 - self._es
        self.drum_segment = float(cable.drum_segment)
        self.efficiency = float(pulley.sheave_efficiency)
        self.stepwise = cable.viscoelastic or self.efficiency < 1.0
        self._decay = relaxation_decay(cable, self.timestep)
        self.viscoelastic = cable.viscoelastic
        self.sensor_at_pulley = (
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "tension_sensor_at_pulley") >= 0
        )
        # the ropes' state, one array for the compiled update (rope_kernel); the names below
        # are views of its rows, updated in place
        self._state = np.zeros((6, n))
        self.u_p = self._state[kernel.U_P]  # the platform segments' unstretched lengths [m]
        self._u_rate = self._state[kernel.U_RATE]  # u̇_p over the last step [m/s]
        # the dashpots' strains: platform, drum segments
        self.eps_d = self._state[kernel.EPS_D_P : kernel.EPS_D_W + 1]
        self._on = self._state[kernel.ON]  # 1 for an intact cable, 0 for a cut one
        self._on[:] = 1.0
        # the cable's extra length in the groove of a lagging swivel [m]
        self.groove_stretch = self._state[kernel.GROOVE]
        self._consts = np.array([self.es0, self.es_m])
        self._params = np.zeros(7)
        self._params[kernel.ENTRY] = self._entry
        self._params[kernel.DRUM] = self.drum_segment
        self._params[kernel.EFFICIENCY] = self.efficiency
        self._params[kernel.DAMPING] = self._damping_time
        self._params[kernel.TIMESTEP] = self.timestep
        self._params[kernel.DECAY] = self._decay
        self._params[kernel.VISCOELASTIC] = float(self.viscoelastic)
        self._tendon_index = np.asarray(self._tendons, dtype=np.int64)
        self._act_index = np.asarray(self._actuator_ids, dtype=np.int64)
        self._tendon_ids = as_slice(self._tendons)
        self._tilt_rot = np.array([so3_exp(np.array([t[0], t[1], 0.0])) for t in self.pulley_draws])
        self._tilt_quat = np.array([quat_wxyz_from_matrix(R) for R in self._tilt_rot])
        # the swivels' bearing friction: each swivel's yaw φ in its tilted frame (None: aligned
        # with its B_i at the next refresh, as after place()) and its lag α = ψ − φ
        self.swivel_arm = 0.5 * pulley.swivel_friction * pulley.swivel_bore
        self._swivel_yaw: np.ndarray | None = None
        self.swivel_lag = np.zeros(n)
        sheaves = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, sheave_geom(i)) for i in range(n)
        ]
        self._sheave_centre = model.geom_pos[sheaves][:, [0, 2]].copy()
        self._wrap_radius = model.geom_size[sheaves, 0].copy()

    # ------------------------------------------------------------------ truth
    @property
    def cable_lengths(self) -> np.ndarray:
        """The platform segments' lengths, A_i over the sheave to B_i (m,) [m].

        MuJoCo's wrapped tendon less the entry segment, with the swivels aligned, plus the
        groove's stretch of each lagging swivel (:func:`~cdpr_twin.sim.rope_kernel.groove_stretch`).
        """
        return self.data.ten_length[self._tendons] - self._entry + self.groove_stretch

    @property
    def pulley_tensions(self) -> np.ndarray:
        """The tensions on the winch side of the sheaves (the drum segments') (m,) [N]."""
        if self.stepwise and self.drum_segment > 0.0:
            return np.where(self.cable_enabled, np.maximum(self.drum_tensions, 0.0), 0.0)
        return self.tensions

    @property
    def drum_tensions(self) -> np.ndarray:
        """The drum segments' elastic tensions at the last rope update (m,) [N] (< 0: slack)."""
        lw = self.drum_segment
        eps_w = lw / (self.data.act[self._actuators] + lw - self.u_p) - 1.0
        return sls_tension(eps_w, self.eps_d[1], self.es0, self.es_m)

    @property
    def sensed_tensions(self) -> np.ndarray:
        """What the tension sensors measure (m,) [N]: at the pulleys or at B_i (robot data)."""
        return self.pulley_tensions if self.sensor_at_pulley else self.tensions

    # ------------------------------------------------------------------ physics
    def disable_cable(self, i: int) -> None:
        """Cut cable i (from 0): see :meth:`Physics.disable_cable`."""
        if 0 <= i < self.n_cables:
            self._on[i] = 0.0
        super().disable_cable(i)

    def place(self, T_base_platform: np.ndarray) -> None:
        """Put the platform at a pose kinematically, swivels aligned (:meth:`Physics.place`)."""
        self._swivel_yaw = None
        super().place(T_base_platform)

    def _rest_lengths(self, T_base_platform: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Rest lengths holding τ with every segment relaxed at τ (a robot long at rest).

        The platform segments' lengths are MuJoCo's own (tilted swivels, offset sheaves).
        """
        self.data.act[self._actuators] = 1.0  # (any state: only the lengths are read)
        self.u_p[:], self.eps_d[:] = 1.0, 0.0
        self._on[:] = 1.0  # (reset() enables every cable)
        self.place(T_base_platform)
        length = self.data.ten_length[self._tendons] - self._entry
        eps = tau / self._es
        self.u_p[:] = length / (1.0 + eps)
        self._u_rate[:] = 0.0
        self.eps_d[:] = eps
        return self.u_p + self.drum_segment / (1.0 + eps) - self.drum_segment

    def _drum_loads(self) -> tuple[np.ndarray, np.ndarray]:
        """The drum segments' forces (m,) [N] and the ropes' stiffnesses E₀/(l0 + l_d) (m,) [N/m].

        What pulls a drum inside its gearbox's play: the whole rope's instantaneous stiffness.
        """
        l0 = self.data.act[self._actuators]
        return self.pulley_tensions, self.es0 / (l0 + self.drum_segment)

    def refresh(self) -> None:
        """Turn the swivels, point MuJoCo's at their B_i, and set the cables' forces.

        MuJoCo's swivels stay aligned with B_i: its cylinder wrap of a turned sheave is a helix
        that spreads the sideways offset over the whole tendon, entry segment included, and
        shortens the cable (by ≈ ρ·α²·(h + r·θ)/(2ℓ), 0.7 µm at 0.01 rad) where the cable in
        a groove lengthens (``rope_kernel.groove_stretch``, 0.05 µm). A lagging swivel's cable
        is MuJoCo's aligned one plus its groove stretch; its exit point moves sideways by
        x_t·sin α (≤ 10 µm at ACROBOT's lags), which turns the cable's direction at B_i by
        ≤ 2e-5 rad, left out.
        """
        d = self.data
        lvec = d.site_xpos[self._anchors] - self._a
        local = np.einsum("nji,nj->ni", self._tilt_rot, lvec)  # in each swivel's tilted frame
        psi = np.arctan2(local[:, 1], local[:, 0])
        if self.swivel_arm > 0.0:
            self._turn_swivels(psi, local)
        half = 0.5 * psi
        yaw = np.zeros((self.n_cables, 4))
        yaw[:, 0], yaw[:, 3] = np.cos(half), np.sin(half)
        quat = self._quat_buf
        for i in range(self.n_cables):
            mujoco.mju_mulQuat(quat[i], self._tilt_quat[i], yaw[i])
        d.mocap_quat[self._mocap] = quat
        if self.stepwise:
            self._update_rope(relax=False)
            return
        l0 = d.act[self._actuators]
        on = (l0 > 0) & self.cable_enabled
        k = np.divide(self.es0, l0 + self.drum_segment, out=np.zeros(self.n_cables), where=on)
        self._gain[:, 0] = k
        self._bias[:, :3] = k[:, None] * self._bias_unit
        if self.swivel_arm > 0.0:
            self._bias[:, 0] -= k * self.groove_stretch

    def _turn_swivels(self, psi: np.ndarray, local: np.ndarray) -> None:
        """Let the swivels follow their cables' azimuths ψ (m,) [rad] by Coulomb's law.

        Between refreshes a swivel holds its yaw: the law is applied to ψ sampled every
        ``align_every`` steps: between refreshes a swivel lags by up to ψ̇·(align_every·h)
        more (20 ms in the paper scenarios: 5e-4 rad at 1 cm/s, a tenth of α*).
        """
        if self._swivel_yaw is None:
            self._swivel_yaw = psi.copy()
        taut = (super().tensions > 0.0) & self.cable_enabled
        kernel.turn_swivels(
            psi,
            np.hypot(local[:, 0], local[:, 1]),
            np.ascontiguousarray(local[:, 2]),
            self._swivel_yaw,
            taut,
            self._sheave_centre,
            self._wrap_radius,
            self.swivel_arm,
            self.swivel_lag,
            self._state,
        )

    def step(self, n: int) -> None:
        """Advance n physics steps (see :meth:`Physics.step`); ropes with state: one by one."""
        if not self.stepwise:
            if self.cable.strain_damping:
                self._step_damping_strain(n)
            else:
                super().step(n)
            return
        dt, m, d = self.timestep, self.model, self.data
        while n > 0:
            chunk = min(n, self.align_every)
            chunk = fire_due(self._hooks, d.time, dt, chunk) if self._hooks else chunk
            self.refresh()
            self._drive_winches(chunk * dt)
            mujoco.mj_step(m, d)
            # the compiled update (the hot path: one call per physics step)
            update, args = kernel.update_ropes, self._kernel_args()
            for _ in range(chunk - 1):
                update(*args, True)
                mujoco.mj_step(m, d)
            update(*args, True)
            n -= chunk
        self._check_state()

    def _step_damping_strain(self, n: int) -> None:
        """:meth:`Physics.step` with the damping on the strain rate, for ropes without state.

        A cable of stiffness k = E₀/(l0 + l_d) strains at (L̇ − ((L + l_d)/(l0 + l_d))·l̇0)/
        (l0 + l_d): its damping pulls k·η·(L̇ − ((L + l_d)/(l0 + l_d))·l̇0), l̇0 the winch's
        rate over the chunk (MuJoCo's ``ctrl``).
        """
        dt, d = self.timestep, self.data
        while n > 0:
            chunk = min(n, self.align_every)
            chunk = fire_due(self._hooks, d.time, dt, chunk) if self._hooks else chunk
            self.refresh()
            self._drive_winches(chunk * dt)
            lw = self.drum_segment
            share = (self.cable_lengths + lw) / (d.act[self._actuators] + lw)
            paid = self._damping_time * share * d.ctrl[self._actuators]
            self._bias[:, 0] = self._gain[:, 0] * (self._entry + paid - self.groove_stretch)
            mujoco.mj_step(self.model, d, nstep=chunk)
            n -= chunk
        self._check_state()

    def _kernel_args(self) -> _KernelArgs:
        """The arrays :func:`~cdpr_twin.sim.rope_kernel.update_ropes` reads and writes."""
        d = self.data
        return (
            d.ten_length,
            d.act,
            self._tendon_index,
            self._act_index,
            self._state,
            self._consts,
            self._params,
            self._gain,
            self._bias,
        )

    def _update_rope(self, relax: bool) -> None:
        """Slide the cables over the sheaves, relax the dashpots, set the platform forces.

        Args:
            relax: advance the dashpots by one physics step (False: only set the forces).
        """
        kernel.update_ropes(*self._kernel_args(), relax)
