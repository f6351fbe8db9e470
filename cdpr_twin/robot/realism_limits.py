"""The largest realism magnitudes a scenario may ask for, each with the reason it is the limit.

Real robots and cameras stay far inside these: beyond them a draw breaks the physics (a
non-positive radius), the arithmetic (float32 overflow), the memory, or the detector. The
robot's calibration errors (``[truth]``), the tension sensors' noise (``[sensors]``,
``[realism.tension]``) and a failed sensor's reading are bounded here too.
"""

from __future__ import annotations

import math

from cdpr_twin.options import OptionError

MAX_RELATIVE_STD = 0.1
"""The largest per-robot relative std of a positive quantity (a radius, a focal length, a
gain): a non-positive draw is then a 10σ event; built and calibrated parts are within 1 %."""
MAX_FULL_WELL_E = 1e30
"""The largest full well [e-] the float32 frame arithmetic holds without overflow."""
MAX_LATENCY_TICKS = 100
"""The longest camera latency [control ticks] (4 s at 25 Hz)."""
MAX_CENTER_ERROR_STD_PX = 20.0
"""The largest per-robot std of the calibrated principal point [px]: calibrations leave
0.3–1.3 px (``models/acrobot/README.md``), and a 10σ draw stays inside a 640×480 frame."""
MAX_DISTORTION_ERROR_STD = 0.1
"""The largest per-robot std of a calibrated distortion coefficient: calibrations leave
3e-4–7e-3; at 0.1 a 10σ draw moves k1 by 1, a different lens."""
MAX_HOMING_POSITION_STD = 0.05
"""The largest homing repeatability [m] per axis: a robot that homes farther off than this
starts somewhere else (set ``start.pose``); CDPRs home within millimetres."""
MAX_HOMING_ROTATION_STD = math.radians(5.0)
"""The largest homing repeatability [rad] per axis (5°; CDPRs home within tenths of one)."""

MAX_POSITION_ERROR_STD = 1.0
"""The largest per-axis std of a point's calibration error [m] (exit and anchor points, camera
mount, tag): assembly and calibration leave millimetres (``paper_open_loop``: 12 mm at the exit
points); a point a metre off is another robot than its description."""
MAX_ROTATION_ERROR_STD = math.radians(10.0)
"""The largest per-axis std of a mount's calibration error [rad] (10°): a hand-eye calibration
and a tag placed by hand are good to 0.3°; at 10° a 3σ draw turns the camera 30° away."""
MAX_PULLEY_RADIUS_STD = 0.01
"""The largest std of a sheave's radius [m] (1 cm): sheaves are machined to ±0.2 mm, and a draw
off by centimetres is another pulley (ACROBOT's sheaves have a 4.5 mm radius)."""
MAX_TENSION_NOISE_STD = 1000.0
"""The largest std of a tension reading's noise or bias [N]: sensors repeat to 0.1 % of their
span or better (ACROBOT 0.01 N of 100 N, COGIRO 5 N of 7 kN); 1 kN is ten times the whole span
of ACROBOT's sensors, a reading that says nothing of the tension."""
TENSION_NOISE_WHY = " N (beyond the span of ACROBOT's sensors tenfold: a reading says nothing)"
"""Why :data:`MAX_TENSION_NOISE_STD` bounds a tension noise, as a message says it."""
MAX_TENSION_READING = 1e6
"""The largest force a failed tension sensor may read [N], either way (1 MN): over 150 times
the top of the largest shipped robot's range (COGIRO's 6 kN); beyond it a reading is no force
a cable robot's sensor outputs (1e300 was accepted, and read for the rest of the run)."""


def check_relative_std(field: str, std: float, what: str) -> None:
    """Refuse a relative std that could draw a non-positive ``what`` (> :data:`MAX_RELATIVE_STD`).

    Raises:
        OptionError: naming ``field``.
    """
    if std > MAX_RELATIVE_STD:
        raise OptionError(
            field,
            f"must be ≤ {MAX_RELATIVE_STD:g} (a relative std: at {std:g} a draw of 1 + std·z "
            f"makes the {what} ≤ 0 once in {1 / _tail(1 / std):.3g} robots), got {std:g}",
        )


def check_at_most(field: str, value: float, bound: float, unit_why: str) -> None:
    """Refuse ``value`` above ``bound``: "must be ≤ {bound}{unit_why}, got {value}".

    Raises:
        OptionError: naming ``field``.
    """
    if value > bound:
        raise OptionError(field, f"must be ≤ {bound:g}{unit_why}, got {value:g}")


def _tail(k: float) -> float:
    """P(z < −k) for a standard normal z."""
    return 0.5 * math.erfc(k / math.sqrt(2.0))
