"""The CDPR's geometric and physical description, as a frozen value (numpy only).

A :class:`CdprGeometry` is read from an MJCF file by :mod:`cdpr_twin.sim.model`: the nominal
geometry that estimators and controllers use, and the twin's true (deviated) geometry, come from
the same model file, so there is one source of truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdpr_twin.math.se3 import check_rigid

GRAVITY = 9.81
"""Standard gravity used by the model files [m/s²]."""


def _frozen(a: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    out = np.array(a, dtype=float)
    if out.shape != shape:
        raise ValueError(f"CdprGeometry.{name} must have shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"CdprGeometry.{name} contains NaN or inf: {out}")
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class CdprGeometry:
    """Geometry and physical constants of an m-cable CDPR.

    Attributes:
        a_base: (m, 3) exit points A_i in F_b [m]: the sheave point on each swivel axis.
        b_platform: (m, 3) anchor points B_i in F_p [m].
        pulley_radius: (m,) sheave radius r_p of each pulley [m].
        es: (m,) axial stiffness E·S of each cable [N].
        mass: platform mass [kg].
        com_platform: (3,) platform centre of mass in F_p [m].
        gravity: (3,) gravity acceleration in F_b [m/s²].
        T_platform_cam: (4, 4) camera mounting, OpenCV camera frame (x right, y down, z forward).
        frame_min: (3,) lower corner of the frame's inner box in F_b [m] (workspace bound).
        frame_max: (3,) upper corner of the frame's inner box in F_b [m].
        tension_min: lowest admissible cable tension [N] (wrench-feasible workspace).
        tension_max: highest admissible cable tension [N] (``inf``: unbounded).
        linear_density: the cables' mass per unstretched metre [kg/m] (0: massless).
        sensors_at_pulleys: the tension sensors sit at the exit pulleys (the upper end of each
            span), not at the anchor points B_i; with heavy cables they read more.
    """

    a_base: np.ndarray
    b_platform: np.ndarray
    pulley_radius: np.ndarray
    es: np.ndarray
    mass: float
    com_platform: np.ndarray
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -GRAVITY]))
    T_platform_cam: np.ndarray = field(default_factory=lambda: np.eye(4))
    frame_min: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))
    frame_max: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    tension_min: float = 2.0
    tension_max: float = 75.0
    linear_density: float = 0.0
    sensors_at_pulleys: bool = False

    def __post_init__(self) -> None:
        a = np.asarray(self.a_base)
        m = a.shape[0] if a.ndim == 2 else -1
        if m < 6:
            raise ValueError(f"CdprGeometry.a_base must be (m, 3) with m ≥ 6 cables, got {a.shape}")
        object.__setattr__(self, "a_base", _frozen(self.a_base, (m, 3), "a_base"))
        object.__setattr__(self, "b_platform", _frozen(self.b_platform, (m, 3), "b_platform"))
        r = np.broadcast_to(np.asarray(self.pulley_radius, dtype=float), (m,))
        object.__setattr__(self, "pulley_radius", _frozen(r, (m,), "pulley_radius"))
        es = np.broadcast_to(np.asarray(self.es, dtype=float), (m,))
        object.__setattr__(self, "es", _frozen(es, (m,), "es"))
        object.__setattr__(self, "com_platform", _frozen(self.com_platform, (3,), "com_platform"))
        object.__setattr__(self, "gravity", _frozen(self.gravity, (3,), "gravity"))
        object.__setattr__(
            self, "T_platform_cam", _frozen(self.T_platform_cam, (4, 4), "T_platform_cam")
        )
        lo = np.array(self.frame_min, dtype=float)
        hi = np.array(self.frame_max, dtype=float)
        lo.flags.writeable = hi.flags.writeable = False
        object.__setattr__(self, "frame_min", lo)
        object.__setattr__(self, "frame_max", hi)
        if np.any(self.pulley_radius < 0) or np.any(self.es <= 0) or not self.mass > 0:
            raise ValueError("CdprGeometry needs pulley_radius ≥ 0, es > 0 and mass > 0")
        if not 0 <= self.tension_min < self.tension_max:
            raise ValueError(
                f"CdprGeometry needs 0 ≤ tension_min < tension_max, got {self.tension_min}, "
                f"{self.tension_max}"
            )

    @property
    def n_cables(self) -> int:
        """Number of cables m."""
        return self.a_base.shape[0]

    def tension_bounds(
        self, tension_min: float | None = None, tension_max: float | None = None
    ) -> tuple[float, float]:
        """Tension bounds [N]: the ones given, the geometry's where ``None``."""
        lo = self.tension_min if tension_min is None else float(tension_min)
        return lo, self.tension_max if tension_max is None else float(tension_max)

    def check_pose_inside(self, T_base_platform: np.ndarray, what: str = "pose") -> np.ndarray:
        """Check a platform pose: rigid, and every anchor point inside the frame's inner box.

        Returns:
            The pose as a float (4, 4) array.

        Raises:
            ValueError: naming the problem and the fix.

        Args:
            T_base_platform: (4, 4) platform pose.
            what: how to name the pose in the error message.
        """
        T = check_rigid(T_base_platform, what)
        b = self.b_platform @ T[:3, :3].T + T[:3, 3]
        outside = np.any((b < self.frame_min) | (b > self.frame_max), axis=1)
        at = f"{what} at position {np.round(T[:3, 3], 4).tolist()} m"
        if np.any(outside):
            raise ValueError(
                f"{at} puts anchor points {(np.flatnonzero(outside) + 1).tolist()} outside the "
                f"frame {np.round(self.frame_min, 3).tolist()}…"
                f"{np.round(self.frame_max, 3).tolist()} m; choose a pose inside the workspace"
            )
        if T[2, 3] >= (z_exit := self.a_base[:, 2].min()):
            raise ValueError(
                f"{at} is not below the lowest exit point (z = {z_exit:.3f} m), where a "
                "suspended robot's platform hangs; choose a lower pose, or check the exit points"
            )
        return T
