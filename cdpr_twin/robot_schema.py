"""The robot description's typed TOML access, and its winch, tension-sensor and payload tables.

:class:`_Table` reads one table of a ``robot.toml`` with one-line :class:`RobotError` naming the
file and ``table.key``; :func:`tension_sensors` and :func:`payload` read the sections that
describe the tension sensors and the rated payload (numpy + tomllib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

SENSOR_LOCATIONS = ("anchor", "pulley")
"""Where a robot's tension sensors sit on each cable: at the platform's anchor point B_i, or at
the exit pulley (winch side). With heavy cables they read different tensions."""


class RobotError(ValueError):
    """A robot description file is missing, malformed, or has a bad field."""


def _frozen(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


class _Table:
    """Typed access to one TOML table; errors name the file and ``table.key``."""

    def __init__(self, source: Path, table: dict, where: str) -> None:
        self.source, self.table, self.where, self.used = source, table, where, set()

    def fail(self, key: str, problem: str) -> RobotError:
        return RobotError(f"{self.source}: {self.where}.{key}: {problem}")

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key in self.table:
            return self.table[key]
        if default is ...:
            raise self.fail(key, "missing (see models/acrobot/robot.toml for the schema)")
        return default

    def number(self, key: str, default: Any = ..., positive: bool = False) -> float:
        v = self.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(key, f"must be a finite number, got {v!r}")
        if positive and not v > 0:
            raise self.fail(key, f"must be > 0, got {v!r}")
        return float(v)

    def array(self, key: str, shape: tuple[int, ...], default: Any = ...) -> np.ndarray:
        """A numeric array of ``shape`` (``-1``: any length ≥ 1 on that axis)."""
        v = self.get(key, default)
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError):
            raise self.fail(key, f"must be an array of numbers of shape {shape}") from None
        if a.ndim != len(shape) or any(
            s not in (-1, n) for s, n in zip(shape, a.shape, strict=True)
        ):
            want = "×".join("m" if s == -1 else str(s) for s in shape)
            raise self.fail(key, f"must have shape {want}, got {'×'.join(map(str, a.shape))}")
        if not np.all(np.isfinite(a)) or any(isinstance(x, bool) for x in np.ravel(v)):
            raise self.fail(key, "must hold finite numbers only")
        return _frozen(a)

    def quaternion(self, key: str) -> np.ndarray:
        """A (4,) wxyz orientation: any non-zero length (it is normalised where it is used)."""
        q = self.array(key, (4,))
        if not np.linalg.norm(q) > 1e-9:
            raise self.fail(key, f"must be a non-zero quaternion [w, x, y, z], got {q.tolist()}")
        return q

    def per_cable(self, key: str, m: int, default: Any = ...) -> np.ndarray:
        """One number for all cables, or a list of m numbers."""
        v = self.get(key, default)
        a = self.array(key, (m,)) if isinstance(v, list) else np.full(m, self.number(key))
        if np.any(a <= 0):
            raise self.fail(key, "must be > 0 for every cable")
        return _frozen(a)

    def string(self, key: str, default: Any = ...) -> str:
        v = self.get(key, default)
        if not isinstance(v, str) or not v:
            raise self.fail(key, f"must be a non-empty string, got {v!r}")
        return v

    def integer(self, key: str, default: Any = ...) -> int:
        v = self.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise self.fail(key, f"must be a whole number ≥ 0, got {v!r}")
        return v

    def done(self) -> None:
        extra = sorted(set(self.table) - self.used)
        if extra:
            raise self.fail(extra[0], "unknown key (a typo? see models/acrobot/robot.toml)")


@dataclass(frozen=True)
class TensionSensorSpec:
    """The robot's tension sensors (one per cable), from their datasheet.

    Attributes:
        range: (min, max) calibrated range [N].
        accuracy: bound ±a on the total error [N] (a datasheet's accuracy).
        repeatability: 1σ of the reading-to-reading noise [N].
        location: ``"anchor"`` (at B_i, on the platform) or ``"pulley"`` (at the exit pulley).
    """

    range: tuple[float, float]
    accuracy: float
    repeatability: float
    location: str


def tension_sensors(t: _Table) -> TensionSensorSpec:
    """``[tension_sensors]``: range_n, accuracy_n, repeatability_n, location."""
    lo, hi = (float(v) for v in t.array("range_n", (2,)))
    if not lo <= 0.0 < hi:  # a slack cable reads 0 N
        raise t.fail("range_n", f"must be [min, max] with min ≤ 0 < max (a slack cable's 0 N "
                     f"in range), got {[lo, hi]}")  # fmt: skip
    accuracy = t.number("accuracy_n", positive=True)
    repeatability = t.number("repeatability_n", positive=True)
    location = t.string("location")
    if location not in SENSOR_LOCATIONS:
        raise t.fail("location", f"must be one of {', '.join(SENSOR_LOCATIONS)}, got {location!r}")
    return TensionSensorSpec((lo, hi), accuracy, repeatability, location)


def payload(t: _Table) -> float:
    """``[payload]``: the rated payload max_mass_kg [kg] (≥ 0; 0: none rated)."""
    v = t.number("max_mass_kg")
    if v < 0:
        raise t.fail("max_mass_kg", f"must be ≥ 0, got {v!r}")
    return v
