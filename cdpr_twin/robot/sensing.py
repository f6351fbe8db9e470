"""What a robot description says of its sensing, filled into a ``[realism]`` profile.

A profile's ``nan`` fields (the drum radius, the tension sensors' range and accuracy) and its
``repeatability_noise`` take the robot's data (``robot.toml`` → the model's ``<numeric>``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import Realism


@dataclass(frozen=True)
class RobotSensing:
    """What a robot description says of its winches and tension sensors (SI units).

    Attributes:
        drum_radius: the drums' radius [m].
        tension_range: (min, max) the sensors' calibrated range [N].
        accuracy: the sensors' accuracy, a bound ±a on the error [N].
        repeatability: 1σ of their reading noise [N].
    """

    drum_radius: float
    tension_range: tuple[float, float]
    accuracy: float
    repeatability: float


def for_robot(realism: Realism, robot: RobotSensing) -> Realism:
    """The profile with its robot-data fields (``nan``, ``repeatability_noise``) filled in.

    The accuracy becomes a rectangular bias, std a/√3 (GUM 4.3.7; see :class:`TensionRealism`).

    Raises:
        OptionError: naming ``realism.tension.range_min``/``range_max`` when the scenario sets
            one and the range, with the robot's value for the other, does not hold 0 N.
    """
    w, t = realism.winch, realism.tension
    if math.isnan(w.drum_radius):
        w = replace(w, drum_radius=robot.drum_radius)
    lo, hi = robot.tension_range
    filled = {
        "range_min": lo if math.isnan(t.range_min) else t.range_min,
        "range_max": hi if math.isnan(t.range_max) else t.range_max,
        "bias_std": robot.accuracy / math.sqrt(3.0) if math.isnan(t.bias_std) else t.bias_std,
    }
    if t.repeatability_noise and math.isnan(t.noise_std):
        filled["noise_std"] = robot.repeatability
    low, high = filled["range_min"], filled["range_max"]
    set_min, set_max = not math.isnan(t.range_min), not math.isnan(t.range_max)
    # a slack cable reads 0 N: every load cell's range holds it (the model's own range is the
    # model's data, checked in robot descriptions; a scenario's is checked here)
    if (set_min or set_max) and not low <= 0.0 < high:
        given = "range_max" if (set_max and not high > 0.0) or not set_min else "range_min"
        raise OptionError(
            f"realism.tension.{given}",
            f"the readings' range {low:g}…{high:g} N (the robot's {lo:g}…{hi:g} N where not "
            "set) must hold 0 N, the slack cable's reading, with range_min ≤ 0 < range_max",
        )
    return replace(realism, winch=w, tension=replace(t, **filled))
