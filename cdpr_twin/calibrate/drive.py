"""How a calibration drives the robot: open-loop moves between poses and cable tightening.

Both act only as the robot's own software can: the moves from the *nominal* model's cable
length changes, the tightening from the tension readings and the nominal model's statics.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg import null_space
from scipy.optimize import linprog

from cdpr_twin.controllers.open_loop import Segment
from cdpr_twin.math.kinematics import cable_lengths, jacobian
from cdpr_twin.math.se3 import so3_log

SPEED = 0.16
"""Cruise speed of the moves between poses [m/s] (0.2 m/rad for rotations); the swing it
leaves decays within the rest that follows (``acquire.SWING``)."""

TIGHTEN_TARGET = 3.0
"""Tightening ends once every cable reads at least this [N]. (With the earlier loop, which
only reeled low cables in: ending at 2.5 N instead, with rests of 0.3 s instead of
``acquire.SETTLE``'s 0.6 s, was 4 % faster over robots 1–20, 64.1 s against 66.8 s median,
but left 1–2 % of robot 8's poses with a cable under 1 N by the readings, against none, and
its calibrated exit points' shape 0.60, 0.46 and 0.38 mm off against 0.32, 0.27 and 0.34 mm
in calibrations with other noise; over the 20 robots paired with the run before, no trend either
way. Kept: the cautious settings.)"""

TIGHTEN_AIM = TIGHTEN_TARGET + 0.5
"""The least tension the internal-force step aims at [N] (above the target: the readings'
noise and the model's error do not leave a cable just under it)."""

TIGHTEN_GAIN = 0.6
"""Share of the internal-force step commanded per tick."""

SPREAD = 1.0
"""Tightening ends only once no cable is this far from the least-total distribution [N]: the
tensions at a pose do not depend on how the robot arrived (a move that keeps the last pose's
length correction may arrive with every cable taut but some far above the target)."""

SLACK = 0.5
"""A cable reading less is slack [N]."""

TIGHTEN_SPEED = 0.002
"""Speed at which a slack cable is reeled in [m/s]."""

TIGHTEN_RATE = 50.0
"""The tension loop's rate while tightening [Hz]: a slack cable that becomes taut is stopped
within 40 µm of reeling (at 25 Hz, 80 µm: newtons more, which unload its neighbours)."""


def move(robot, geom, T_from: np.ndarray, T_to: np.ndarray, period: float) -> None:
    """Drive open loop along a quintic line, rates from the nominal lengths' changes.

    ``robot`` is what advances with the rates: a calibration's
    :class:`~cdpr_twin.run.episode.Episode`, or a bare :class:`~cdpr_twin.sim.Physics`
    (both have ``advance(duration, cable_rates)``); nothing is read on the way.

    Each cable changes by the nominal model's length change along the line: the correction the
    last pose needed (what tightening reeled in or let out there, against the nominal lengths)
    is kept, as the model's error changes little between the tour's neighbours. Paying it
    back along the way, the robot arrived on the nominal lengths with more slack to reel in:
    robots 1, 8 and 19 recorded 951, 1207 and 1221 simulated s, against 849, 911 and 848 s.
    Over robots 1–20 the calibration's accuracy stayed as it was, robot by robot
    (``docs/calibration/``: the exit points' paired differences' median −0.003 mm).
    """
    dist = np.linalg.norm(T_to[:3, 3] - T_from[:3, 3])
    ang = np.linalg.norm(so3_log(T_from[:3, :3].T @ T_to[:3, :3]))
    n = max(int(np.ceil((dist + 0.2 * ang) / SPEED / period * 1.875)), 10)  # peak ṡ = 1.875
    seg = Segment(T_from, T_to, n * period)
    lengths = cable_lengths(geom, T_from, "pulley")
    for k in range(1, n + 1):
        nxt = cable_lengths(geom, seg.pose(k * period), "pulley")
        robot.advance(period, (nxt - lengths) / period)
        lengths = nxt


def tighten_with(
    advance: Callable[[float, np.ndarray], None],
    read_tensions: Callable[[], np.ndarray],
    timestep: float,
    geom,
    T: np.ndarray,
    timeout: float = 8.0,
) -> int:
    """Bring every cable to at least :data:`TIGHTEN_TARGET`, from the tension readings.

    The true robot differs from the model, so after an open-loop move some cables hang slack
    (the platform rests on six, which carry no information on the geometry). Like a real
    CDPR's tensioning step this uses the tension readings and the robot's *nominal* model
    ``geom`` at the commanded pose ``T``, at :data:`TIGHTEN_RATE`:

    - while a cable reads slack (below :data:`SLACK`), the slack ones are reeled in at
      :data:`TIGHTEN_SPEED` (how much slack is unknown to the software);
    - once all are taut, the tensions are moved along the platform's internal forces, the
      null space of the nominal structure matrix Wᵀ (a change N·α of the tensions that leaves
      the platform's wrench, hence its pose, as it is): to the least total tension with every
      cable at :data:`TIGHTEN_AIM` or more (a linear program on α), or, where the robot
      cannot hold every cable that high, to the greatest least tension. The lengths that make
      that change are −N·α / k (k = E·S / l, the nominal stiffness), commanded
      :data:`TIGHTEN_GAIN` of the way per tick (the winches' lag delivers the rest later).

    Args:
        advance: runs the winches at the given rates [m/s] for the given time [s] (a
            calibration's ``Episode.advance``, or ``Physics.advance``).
        read_tensions: reads the tension sensors now, (m,) [N] (all this reads of the robot).
        timestep: the physics' time step [s] (the loop's period is a whole number of them).
        geom: the nominal geometry.
        T: (4, 4) the commanded pose.
        timeout: [s]; 8 s reels in up to 16 mm of slack (robot 19, its exit points 12 mm off,
            needed 7.3 s at one of the six poses of ``tests/calibrate/test_calibrate_drive.py``).

    It ends once every cable reads at least :data:`TIGHTEN_TARGET` (or, where the robot
    cannot hold that, the greatest least tension less 0.1 N) and none is :data:`SPREAD` or
    more from the distribution the step aims at. With the earlier loop, which only reeled low
    cables in, 11 of robot 1's 60 poses of one segment spent the whole timeout, its cables a
    little under 3 N, walking the platform along the directions that change no tension; now
    none does (180 of its 386 simulated s were tightening; 114 s with these steps alone).

    Returns:
        The loop's ticks before it ended: 0 if the cables already read so, ``-1`` if they
        did not at the timeout.
    """
    dt = timestep * max(1, round(1.0 / TIGHTEN_RATE / timestep))
    N = null_space(jacobian(geom, T, "base", "pulley").T)  # (m, m − 6) internal forces
    k = geom.es / cable_lengths(geom, T, "pulley")  # [N/m]
    for tick in range(round(timeout / dt)):
        tau = read_tensions()
        slack = tau < SLACK
        if slack.any():
            rates = np.where(slack, -TIGHTEN_SPEED, 0.0)
        else:
            change, best = _internal_forces(N, tau, TIGHTEN_AIM, geom.tension_max)
            if tau.min() >= min(TIGHTEN_TARGET, best - 0.1) and np.abs(change).max() < SPREAD:
                return tick
            rates = -TIGHTEN_GAIN * change / k / dt
            rates *= min(1.0, TIGHTEN_SPEED / np.abs(rates).max())
        advance(dt, rates)
    return -1


def tighten(physics, sensors, geom, T: np.ndarray, timeout: float = 8.0) -> int:
    """:func:`tighten_with` on a bare simulated robot and its sensors (no run around them).

    Args:
        physics: the simulated robot (:class:`~cdpr_twin.sim.Physics`).
        sensors: its sensors (the tension readings, without the camera, are all it reads).
        geom: the nominal geometry.
        T: (4, 4) the commanded pose.
        timeout: [s].

    Returns:
        As :func:`tighten_with`.
    """
    return tighten_with(
        physics.advance,
        lambda: sensors.read(None, render=False).tensions,
        physics.timestep,
        geom,
        T,
        timeout,
    )


def _internal_forces(N: np.ndarray, tau: np.ndarray, aim: float, hi: float) -> tuple:
    """The internal-force change N·α toward the least total tension with all at ``aim`` or more.

    Where no α reaches ``aim`` on every cable, the one that maximises the least tension.

    Returns:
        ((m,) tension change [N], the least tension it leads to [N]).
    """
    m, n = N.shape
    bounds = [(None, None)] * n
    upper = np.vstack([-N, N]), np.concatenate([tau - aim, hi - tau])
    lp = linprog(N.sum(axis=0), A_ub=upper[0], b_ub=upper[1], bounds=bounds, method="highs")
    if lp.status == 0:
        change = N @ lp.x
        return change, float((tau + change).min())
    # maximise t with tau + N α ≥ t, tau + N α ≤ hi: variables (α, t)
    A = np.block([[-N, np.ones((m, 1))], [N, np.zeros((m, 1))]])
    c = np.r_[np.zeros(n), -1.0]
    lp = linprog(
        c, A_ub=A, b_ub=np.r_[tau, hi - tau], bounds=[*bounds, (None, None)], method="highs"
    )
    if lp.status != 0:  # not even the readings' own distribution: hold still
        return np.zeros(m), float(tau.min())
    return N @ lp.x[:n], float(lp.x[n])
