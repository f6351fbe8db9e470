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

from cdpr_twin.math.catenary import hangs_vertically

SENSOR_LOCATIONS = ("anchor", "pulley")
"""Where a robot's tension sensors sit on each cable: at the platform's anchor point B_i, or at
the exit pulley (winch side). With heavy cables they read different tensions."""


class RobotError(ValueError):
    """A robot description file is missing, malformed, or has a bad field."""


MIN_TIMESTEP, MAX_TIMESTEP = 1e-5, 0.002
"""Physics step bounds [s]: below, a run takes hours per simulated second; above, the stiff
cables (k ≈ 3e5 N/m) are unstable."""


def _finite(v: Any) -> bool:
    """Whether a TOML number is finite as a float (an integer past 1e308 is not)."""
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _has_bool(v: Any) -> bool:
    """Whether a (nested) TOML array holds a boolean (numpy would read it as 0 or 1)."""
    return isinstance(v, bool) or (isinstance(v, list) and any(_has_bool(x) for x in v))


def _frozen(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


def _shown(v: Any) -> str:
    """A bad value as the error shows it (a 400-digit integer shortened)."""
    text = repr(v)
    return text if len(text) <= 40 else f"{text[:20]}…({len(text)} characters)"


class _Table:
    """Typed access to one TOML table; errors name the file and ``table.key``."""

    def __init__(self, source: Path, table: dict, where: str) -> None:
        self.source, self.table, self.where = source, table, where
        self.used: set[str] = set()

    def fail(self, key: str, problem: str) -> RobotError:
        return RobotError(f"{self.source}: {self.where}.{key}: {problem}")

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key in self.table:
            return self.table[key]
        if default is ...:
            raise self.fail(key, "missing (see models/acrobot/robot.toml for the schema)")
        return default

    def number(
        self, key: str, default: Any = ..., positive: bool = False, infinite: bool = False
    ) -> float:
        """A number (``infinite``: ``inf`` allowed, as "unchecked")."""
        v = self.get(key, default)
        ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        if not ok or not (_finite(v) or (infinite and v == math.inf)):
            what = "a finite number or inf" if infinite else "a finite number"
            raise self.fail(key, f"must be {what}, got {_shown(v)}")
        if positive and not v > 0:
            raise self.fail(key, f"must be > 0, got {v!r}")
        return float(v)

    def array(self, key: str, shape: tuple[int, ...], default: Any = ...) -> np.ndarray:
        """A numeric array of ``shape`` (``-1``: any length ≥ 1 on that axis)."""
        v = self.get(key, default)
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise self.fail(key, f"must be an array of finite numbers of shape {shape}") from None
        if a.ndim != len(shape) or any(
            s not in (-1, n) for s, n in zip(shape, a.shape, strict=True)
        ):
            want = "×".join("m" if s == -1 else str(s) for s in shape)
            raise self.fail(key, f"must have shape {want}, got {'×'.join(map(str, a.shape))}")
        if not np.all(np.isfinite(a)) or _has_bool(v):
            raise self.fail(key, "must hold finite numbers only (no true/false)")
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
        if not isinstance(v, str) or not v or "\0" in v:
            raise self.fail(key, f"must be a non-empty string without NUL, got {_shown(v)}")
        return v

    def boolean(self, key: str, default: Any = ...) -> bool:
        v = self.get(key, default)
        if not isinstance(v, bool):
            raise self.fail(key, f"must be true or false, got {_shown(v)}")
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
        raise t.fail(
            "range_n",
            f"must be [min, max] with min ≤ 0 < max (a slack cable's 0 N in range), got {[lo, hi]}",
        )
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


def check_inertia(t: _Table, inertia: np.ndarray) -> None:
    """Refuse an inertia no rigid body has (``inertia_kg_m2``: 3 moments or 6 entries).

    Its principal moments must be > 0 and each at most the sum of the other two (the triangle
    inequality every mass distribution obeys; MuJoCo refuses the rest without naming the file).
    """
    if len(inertia) == 6:
        ixx, iyy, izz, ixy, ixz, iyz = inertia
        moments = np.linalg.eigvalsh(np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
    else:
        moments = np.asarray(inertia, dtype=float)
    if not np.all(moments > 0):
        raise t.fail(
            "inertia_kg_m2",
            f"must be positive definite, its principal moments are "
            f"{np.round(moments, 6).tolist()} kg·m²",
        )
    if np.any(2 * moments > moments.sum() * (1 + 1e-9)):
        raise t.fail(
            "inertia_kg_m2",
            f"principal moments {np.round(moments, 6).tolist()} "
            "kg·m²: each must be at most the sum of the other two (no rigid body has "
            "another inertia)",
        )


def check_gravity(t: _Table, gravity: np.ndarray, sag: bool) -> None:
    """Refuse a gravity off the vertical for cables with mass (their catenary hangs along z)."""
    if sag and not hangs_vertically(gravity):
        raise t.fail(
            "gravity_m_s2",
            f"must point along -z with cables.sag = true (the cables "
            f"hang in vertical planes), got {gravity.tolist()}",
        )
