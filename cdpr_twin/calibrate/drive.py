"""How a calibration drives the robot: open-loop moves between poses and cable tightening.

Both act only as the robot's own software can: the moves from the *nominal* model's cable
lengths, the tightening from the tension readings.
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.controllers.open_loop import Segment
from cdpr_twin.kinematics import cable_lengths
from cdpr_twin.se3 import so3_log

SPEED = 0.16
"""Cruise speed of the moves between poses [m/s] (0.2 m/rad for rotations); the swing it
leaves decays within the rest that follows (``acquire.SETTLE``)."""

TIGHTEN_TARGET = 3.0
"""Tightening ends once every cable reads at least this [N]. (Ending at 2.5 N instead, with
rests of 0.3 s instead of ``acquire.SETTLE``'s 0.6 s, was 4 % faster over robots 1–20, 64.1 s
against 66.8 s median, but left 1–2 % of robot 8's poses with a cable under 1 N by the
readings, against none, and its calibrated exit points' shape 0.60, 0.46 and 0.38 mm off
against 0.32, 0.27 and 0.34 mm in sessions with other noise; over the 20 robots paired with
the run before, no trend either way. Kept: the cautious settings.)"""

TIGHTEN_SPEED = 0.002
"""Speed at which a slack cable is reeled in [m/s]."""

TIGHTEN_RATE = 50.0
"""The tension loop's rate while tightening [Hz]: a slack cable that becomes taut is stopped
within 40 µm of reeling (at 25 Hz, 80 µm: newtons more, which unload its neighbours)."""


def move(physics, sensors, geom, T_from: np.ndarray, T_to: np.ndarray, period: float) -> None:
    """Drive open loop along a quintic line, rates from the nominal lengths' changes.

    The lengths end at the nominal model's at ``T_to``: what tightening reeled in at the last
    pose is paid back out along the way.
    """
    dist = np.linalg.norm(T_to[:3, 3] - T_from[:3, 3])
    ang = np.linalg.norm(so3_log(T_from[:3, :3].T @ T_to[:3, :3]))
    n = max(int(np.ceil((dist + 0.2 * ang) / SPEED / period * 1.875)), 10)  # peak ṡ = 1.875
    seg = Segment(T_from, T_to, n * period)
    lengths = sensors.read(None, render=False).cable_lengths
    gap = cable_lengths(geom, T_from, "pulley") - lengths
    for k in range(1, n + 1):
        nxt = cable_lengths(geom, seg.pose(k * period), "pulley") - gap * (1.0 - k / n)
        physics.advance(period, (nxt - lengths) / period)
        lengths = nxt


def tighten(physics, sensors, timeout: float = 8.0) -> int:
    """Reel in cables below :data:`TIGHTEN_TARGET` until every cable reads at least that.

    Or until ``timeout`` [s] passes: 8 s reels in up to 16 mm of slack (robot 19, its exit
    points 12 mm off, needed 7.3 s at one of the six poses of
    ``tests/test_calibration_drive.py``).

    The true robot differs from the model, so after an open-loop move some cables hang slack
    (the platform rests on six, which carry no information on the geometry). Like a real
    CDPR's tensioning step this uses the tension readings only, at :data:`TIGHTEN_RATE`: a
    slack cable (below 0.5 N) is reeled in at :data:`TIGHTEN_SPEED`, a taut one below the
    target in proportion to the missing tension. Reeling one cable in unloads others, so a few
    poses end at the timeout with a cable a little under the target (2.9 N at one of the six
    poses of the test; at 25 Hz, 15 of robot 1's first 60 poses did, with 4 s then).

    Returns:
        The loop's ticks that reeled cable in: 0 if every cable already read at least
        :data:`TIGHTEN_TARGET`, ``-1`` if some still read less at the timeout.
    """
    dt = physics.timestep * max(1, round(1.0 / TIGHTEN_RATE / physics.timestep))
    for tick in range(round(timeout / dt)):
        tau = sensors.read(None, render=False).tensions
        low = tau < TIGHTEN_TARGET
        if not low.any():
            return tick
        k = physics.geometry.es / physics.rest_lengths  # the order of magnitude suffices
        missing = TIGHTEN_TARGET + 1.0 - tau
        rate = np.where(tau < 0.5, -TIGHTEN_SPEED, -missing / (k * 0.05))
        physics.advance(dt, np.where(low, np.maximum(rate, -TIGHTEN_SPEED), 0.0))
    return -1
