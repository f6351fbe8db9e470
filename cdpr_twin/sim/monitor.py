"""The robot's plausibility monitor: a simulated robot that reports its own faults.

A real CDPR's safety layer stops the winches when a cable is overloaded, the platform leaves
its workspace or hits the floor, the robot loses its constraint (fewer than six taut cables:
the platform is no longer held in all six directions), or the platform moves faster than the
winches can drive it. The twin's :class:`Monitor` checks the same limits on the simulated
robot's *true* state (it is part of the simulation, like the robot's own safety hardware),
between physics steps (a :class:`~cdpr_twin.sim.events.StepHook`: every refresh chunk, 5 ms on
ACROBOT) and once more at each control tick. Each limit crossed is a :class:`Fault`, kept with
the simulation time it was seen at; the runner stops the run at the tick the fault happens in
(status ``fault: <kind>``) unless the scenario says to continue (``[monitor] on_fault``).

The limits (:class:`MonitorLimits`) are the robot's (``<numeric>`` elements of its model, see
``models/acrobot/README.md`` for ACROBOT's numbers and sources) and its tension sensors' range;
a model without a limit's element leaves that check off. MuJoCo's own warnings (constraint
or contact buffers full, bad inertia…) are faults too; a diverged state raises
:class:`~cdpr_twin.sim.model.SimulationError` from the physics, as without a monitor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import mujoco
import numpy as np

from cdpr_twin.sim.model import numeric

DIVERGENCE_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)
"""Warnings that mean the state is no longer a simulation (the physics raises on them)."""


class FaultKind(StrEnum):
    """What went wrong; a run stopped by it ends with status ``fault: <value>``."""

    BREAKING_LOAD = "cable over its breaking load"
    SENSOR_RANGE = "tension beyond the sensor range"
    OUTSIDE_FRAME = "platform outside the frame"
    ON_FLOOR = "platform on the floor"
    SLACK = "fewer than six taut cables"
    SPEED = "platform faster than the winches can drive it"
    MUJOCO_WARNING = "MuJoCo warning"
    DIVERGED = "simulation diverged"


@dataclass(frozen=True)
class Fault:
    """One fault of the simulated robot.

    Attributes:
        time: simulation time it was seen at [s] (within one refresh chunk of the crossing).
        kind: what went wrong.
        detail: the numbers, in words (which cable, the value, the limit).
        cable: the cable at fault, counted from 1, or 0 for none.
    """

    time: float
    kind: FaultKind
    detail: str
    cable: int = 0

    @property
    def status(self) -> str:
        """The run status this fault ends a run with."""
        return f"fault: {self.kind.value}"

    @property
    def described(self) -> str:
        """The status with its numbers, as the run's marks and the Gym env's ``info`` say it."""
        return f"{self.status} ({self.detail})"

    def as_dict(self) -> dict:
        """For ``summary.json``."""
        out = {"time_s": self.time, "kind": self.kind.value, "detail": self.detail}
        return out | ({"cable": self.cable} if self.cable else {})


@dataclass(frozen=True)
class MonitorLimits:
    """The limits one robot's monitor checks (``inf`` or NaN: that check is off).

    Attributes:
        breaking_load: a cable's breaking load [N].
        sensor_max: the top of the tension sensors' range [N].
        frame_min: (3,) lower corner of the frame the platform origin must stay in [m].
        frame_max: (3,) upper corner [m].
        floor_z: height of the floor [m]; the platform box's lowest corner must stay above it.
        max_speed: the platform's largest plausible linear speed [m/s].
        max_angular_speed: its largest plausible angular speed [rad/s].
        min_taut: fewer taut cables than this (tension > 0) is a loss of constraint.
        slack_time: how long a loss of constraint may last before it is a fault [s] (one
            control period: a transient inside a tick is physics, not a fault).
    """

    breaking_load: float = math.inf
    sensor_max: float = math.inf
    frame_min: tuple[float, float, float] = (-math.inf,) * 3
    frame_max: tuple[float, float, float] = (math.inf,) * 3
    floor_z: float = -math.inf
    max_speed: float = math.inf
    max_angular_speed: float = math.inf
    min_taut: int = 6
    slack_time: float = 0.04


def _numeric_or(model: mujoco.MjModel, name: str, default: float) -> float:
    present = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name) >= 0
    return float(numeric(model, name)[0]) if present else default


def _point(v: np.ndarray) -> tuple[float, float, float]:
    """A (3,) array as a point of floats."""
    x, y, z = map(float, v)
    return x, y, z


def robot_limits(physics, sensor_max: float, slack_time: float) -> MonitorLimits:
    """The limits a model declares in ``<numeric>`` elements.

    ``cable_breaking_load`` [N], ``platform_max_speed`` [m/s], ``platform_max_angular_speed``
    [rad/s], ``floor_height`` [m] (each check is off without its element), and the frame.

    Args:
        physics: the simulated robot (:class:`~cdpr_twin.sim.physics.Physics`): its model and
            the geometry read from it.
        sensor_max: the tension sensors' range top [N].
        slack_time: how long fewer than six cables may be taut [s].
    """
    model, geom = physics.model, physics.geometry
    return MonitorLimits(
        breaking_load=_numeric_or(model, "cable_breaking_load", math.inf),
        sensor_max=float(sensor_max),
        frame_min=_point(geom.frame_min),
        frame_max=_point(geom.frame_max),
        floor_z=_numeric_or(model, "floor_height", -math.inf),
        max_speed=_numeric_or(model, "platform_max_speed", math.inf),
        max_angular_speed=_numeric_or(model, "platform_max_angular_speed", math.inf),
        slack_time=float(slack_time),
    )


def divergence(data: mujoco.MjData) -> list[str]:
    """Names of the divergence warnings MuJoCo raised (empty while the state is sound)."""
    # every count in one read: a warning's own struct is a binding object per look
    counts = data.warning.number.tolist()
    return [mujoco.mjtWarning(w).name for w in _DIVERGENCE_IDS if counts[w] > 0]


_DIVERGENCE_IDS = tuple(map(int, DIVERGENCE_WARNINGS))
_OTHER_WARNINGS = tuple(
    w for w in range(mujoco.mjtWarning.mjNWARNING) if w not in set(DIVERGENCE_WARNINGS)
)


class Monitor:
    """Checks a physics' true state against its robot's limits; a step hook of the physics.

    Args:
        physics: the simulated robot (:class:`~cdpr_twin.sim.physics.Physics`).
        limits: what to check.

    Attributes:
        faults: every fault seen, in time order (each kind once per onset: a limit that stays
            crossed is one fault).
    """

    def __init__(self, physics, limits: MonitorLimits) -> None:
        self.physics, self.limits = physics, limits
        self.faults: list[Fault] = []
        self._half = tuple(map(float, physics.platform_half_size))  # (3,) [m]
        self._active: set[FaultKind] = set()
        self._slack_since = math.nan
        self._warnings = [0] * mujoco.mjtWarning.mjNWARNING  # each warning's count last seen
        self._taken = 0

    def reset(self) -> None:
        """Forget every fault and onset (the robot was just reset)."""
        self.faults, self._taken, self._active = [], 0, set()
        self._slack_since = math.nan
        self._warnings = self.physics.data.warning.number.tolist()

    def next_time(self) -> float:
        """Always due: the monitor looks at every refresh chunk."""
        return self.physics.data.time

    def fire(self, time: float) -> None:
        """Check now (the state the last chunk left)."""
        self.check()

    def take(self) -> list[Fault]:
        """The faults seen since the last call."""
        new = self.faults[self._taken :]
        self._taken = len(self.faults)
        return new

    def check(self) -> None:
        """Check every limit on the current state; record each fault's onset."""
        p, lim = self.physics, self.limits
        if not p.was_reset:
            return
        seen: dict[FaultKind, tuple[str, int]] = {}
        tau = p.tensions
        worst = int(tau.argmax())
        peak = tau.item(worst)
        for kind, limit in (
            (FaultKind.BREAKING_LOAD, lim.breaking_load),
            (FaultKind.SENSOR_RANGE, lim.sensor_max),
        ):
            if peak > limit:
                seen[kind] = (f"cable {worst + 1} at {peak:.1f} N > {limit:g} N", worst + 1)
        self._placement(seen)
        self._constraint(p.taut, seen)
        self._mujoco(seen)
        if seen or self._active:  # (nothing to compare while all is well)
            for kind, (detail, cable) in seen.items():
                if kind not in self._active:
                    self.faults.append(Fault(p.time, kind, detail, cable))
            self._active = set(seen)

    def _placement(self, seen: dict) -> None:
        """Frame, floor and speed limits, on Python floats (a check runs twice a tick)."""
        p, lim = self.physics, self.limits
        q, v = p.platform_state  # views: no copy on the hot path
        x0, y0, z0, w, x, y, z = q.tolist()
        (x_lo, y_lo, z_lo), (x_hi, y_hi, z_hi) = lim.frame_min, lim.frame_max
        # comparisons spelled out: no generator on the hot path (a check runs at every chunk)
        if x0 < x_lo or x0 > x_hi or y0 < y_lo or y0 > y_hi or z0 < z_lo or z0 > z_hi:
            pos = [round(c, 3) for c in (x0, y0, z0)]
            seen[FaultKind.OUTSIDE_FRAME] = (f"origin at {pos} m", 0)
        # the lowest corner: the third row of R against the half sizes, each at its worst sign
        hx, hy, hz = self._half
        reach = hx * abs(2 * (x * z - w * y)) + hy * abs(2 * (y * z + w * x))
        low = z0 - (reach + hz * abs(1 - 2 * (x * x + y * y)))
        if low <= lim.floor_z:
            seen[FaultKind.ON_FLOOR] = (f"lowest corner at z = {low:.4f} m", 0)
        vx, vy, vz, wx, wy, wz = v.tolist()
        speed, turn = math.sqrt(vx * vx + vy * vy + vz * vz), math.sqrt(wx * wx + wy * wy + wz * wz)
        if speed > lim.max_speed or turn > lim.max_angular_speed:
            seen[FaultKind.SPEED] = (
                f"{speed:.2f} m/s, {turn:.2f} rad/s > {lim.max_speed:g} m/s, "
                f"{lim.max_angular_speed:g} rad/s",
                0,
            )

    def _constraint(self, taut_cables: np.ndarray, seen: dict) -> None:
        lim, t = self.limits, self.physics.data.time
        taut = int(np.count_nonzero(taut_cables))
        if taut >= lim.min_taut:
            self._slack_since = math.nan
            return
        if math.isnan(self._slack_since):
            self._slack_since = t
        if t - self._slack_since > lim.slack_time + 1e-9:  # (not a float's last bit)
            seen[FaultKind.SLACK] = (
                f"{taut} taut for {t - self._slack_since:.3f} s > {lim.slack_time:g} s",
                0,
            )

    def _mujoco(self, seen: dict) -> None:
        counts = self.physics.data.warning.number.tolist()
        if counts == self._warnings:  # (the usual case: no warning since the last check)
            return
        last, self._warnings = self._warnings, counts
        new = [w for w in _OTHER_WARNINGS if counts[w] > last[w]]
        if new:
            names = [mujoco.mjtWarning(w).name for w in new]
            seen[FaultKind.MUJOCO_WARNING] = (", ".join(names), 0)
