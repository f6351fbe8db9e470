"""Wrench-feasible workspace of a suspended CDPR (numpy + scipy).

A pose is wrench-feasible when some tension distribution τ with τ_min ≤ τ_i ≤ τ_max holds the
platform's weight there: W τ = w_g with W = Aᵀ (6 × m, the pulley model's cable directions).
:func:`is_feasible` decides it with one linear program (HiGHS); :func:`sample_workspace` does
so on a grid of positions at one orientation, inside the frame; :func:`check_waypoints` is what
scenario validation uses (``cdpr-twin model workspace`` draws a sampled workspace).

Bad input is refused before any work: :func:`spacing_problem` says why a grid spacing cannot
be used (not a finite positive number, no grid point in the frame, more than
:data:`MAX_POINTS` points).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.kinematics import CableModel, gravity_wrench, jacobian
from cdpr_twin.math.se3 import transform, vector_from_pose


def geometry_of(robot) -> CdprGeometry:
    """The nominal :class:`CdprGeometry` of a robot description (no MuJoCo).

    The centre of mass is the description's, else the box centre (a uniform box).

    Args:
        robot: a :class:`cdpr_twin.robot.description.Robot`.
    """
    return CdprGeometry(
        a_base=robot.exit_points,
        b_platform=robot.anchor_points,
        pulley_radius=robot.sheave_radius,
        es=robot.es,
        mass=robot.mass,
        com_platform=robot.box_center if robot.com is None else robot.com,
        gravity=robot.gravity,
        frame_min=robot.frame_min,
        frame_max=robot.frame_max,
        tension_min=float(robot.tension_range[0]),
        tension_max=float(robot.tension_range[1]),
        linear_density=robot.linear_density,
    )


def is_feasible(
    geom: CdprGeometry,
    T_base_platform: np.ndarray,
    tension_min: float | None = None,
    tension_max: float | None = None,
    model: CableModel = "pulley",
) -> bool:
    """Whether a tension distribution within the limits holds the platform at a pose.

    Args:
        geom: the robot.
        T_base_platform: (4, 4) pose.
        tension_min: lowest tension [N] (default: the geometry's).
        tension_max: highest tension [N] (default: the geometry's; may be ``inf``).
        model: cable model for the directions.

    Returns:
        True when W τ = w_g has a solution with every τ_i in [tension_min, tension_max].
    """
    lo = geom.tension_min if tension_min is None else tension_min
    hi = geom.tension_max if tension_max is None else tension_max
    W = jacobian(geom, T_base_platform, "base", model).T
    rhs = gravity_wrench(geom, T_base_platform)
    scale = max(float(np.linalg.norm(rhs)), 1e-12)  # unit wrench: tolerances independent of g·m
    bounds = [(lo / scale, None if np.isinf(hi) else hi / scale)] * geom.n_cables
    lp = linprog(np.zeros(geom.n_cables), A_eq=W, b_eq=rhs / scale, bounds=bounds, method="highs")
    return lp.status == 0


def inside_frame(geom: CdprGeometry, T_base_platform: np.ndarray) -> bool:
    """Whether every anchor point is inside the frame and the platform below the exit points."""
    try:
        geom.check_pose_inside(T_base_platform)
    except ValueError:
        return False
    return True


@dataclass(frozen=True, eq=False)
class Workspace:
    """A sampled wrench-feasible workspace at one orientation.

    Attributes:
        xs, ys, zs: grid coordinates [m] (nx,), (ny,), (nz,).
        inside: (nx, ny, nz) bool, the platform fits inside the frame there.
        feasible: (nx, ny, nz) bool, inside and wrench-feasible.
        rotation: (3, 3) platform orientation used.
        tension_range: (2,) [N].
        spacing: grid spacing [m].
    """

    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    inside: np.ndarray
    feasible: np.ndarray
    rotation: np.ndarray
    tension_range: tuple[float, float]
    spacing: float

    def points(self) -> np.ndarray:
        """The feasible positions, (k, 3) [m]."""
        i, j, k = np.nonzero(self.feasible)
        return np.stack([self.xs[i], self.ys[j], self.zs[k]], axis=1)


MAX_POINTS = 1_000_000
"""The most grid points :func:`sample_workspace` takes (one linear program, ≈ 1 ms, each)."""


def _grid_box(geom: CdprGeometry) -> tuple[np.ndarray, np.ndarray]:
    """The box the grid covers: the frame's inner box, below the lowest exit point."""
    return geom.frame_min, np.minimum(geom.frame_max, geom.a_base[:, 2].min())


def _grid_points(lo: np.ndarray, hi: np.ndarray, spacing: float) -> float:
    """The number of grid points (``np.arange``'s lengths, ``inf`` if huge), without a grid."""
    with np.errstate(over="ignore", divide="ignore"):  # (the product too: 1e-300 m spacing)
        n = np.ceil((hi - (lo + spacing / 2)) / spacing)
        return float(np.prod(np.maximum(n, 0.0)))


def spacing_problem(geom: CdprGeometry, spacing: float) -> str | None:
    """Why a grid spacing cannot sample ``geom``'s workspace, with the fix, or ``None``.

    It must be a finite number > 0, leave at least one grid point in the frame (be below twice
    the frame's smallest inner extent) and give at most :data:`MAX_POINTS` points.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        return "is not a grid spacing: give a finite number > 0 [m], e.g. 0.05"
    lo, hi = _grid_box(geom)
    n = _grid_points(lo, hi, spacing)
    if n == 0:
        extent = float((hi - lo).min())
        return (
            f"leaves no grid point inside the frame: give less than {2 * extent:g} m (twice "
            f"the frame's smallest inner extent, {extent:g} m)"
        )
    if n > MAX_POINTS:
        least = math.ceil((float(np.prod(hi - lo)) / MAX_POINTS) ** (1 / 3) * 1e4) / 1e4
        while _grid_points(lo, hi, least) > MAX_POINTS:
            least += 1e-4
        return (
            f"gives {n:.3g} grid points, more than {MAX_POINTS:,} (about 1 ms each): give at "
            f"least {round(least, 4):g} m"
        )
    return None


def sample_workspace(
    geom: CdprGeometry,
    spacing: float = 0.05,
    rotation: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Workspace:
    """Sample the wrench-feasible workspace on a grid over the frame's inner box.

    Args:
        geom: the robot, with its tension limits and frame.
        spacing: grid spacing [m].
        rotation: (3, 3) platform orientation (default: level, identity).
        progress: called with (points done, points) after each grid plane.

    Returns:
        The sampled :class:`Workspace`.

    Raises:
        ValueError: the spacing cannot be used (:func:`spacing_problem`).
    """
    if problem := spacing_problem(geom, spacing):
        raise ValueError(f"spacing {spacing:g} m {problem}")
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    lo, hi = _grid_box(geom)
    axes = [np.arange(lo[k] + spacing / 2, hi[k], spacing) for k in range(3)]
    inside = np.zeros(tuple(len(a) for a in axes), dtype=bool)
    feasible = np.zeros_like(inside)
    plane = inside.shape[1] * inside.shape[2]
    for idx in np.ndindex(inside.shape):
        T = transform(R, np.array([axes[k][idx[k]] for k in range(3)]))
        inside[idx] = inside_frame(geom, T)
        feasible[idx] = inside[idx] and is_feasible(geom, T)
        if progress is not None and idx[1] == inside.shape[1] - 1 and idx[2] == inside.shape[2] - 1:
            progress((idx[0] + 1) * plane, inside.size)
    x, y, z = axes
    return Workspace(x, y, z, inside, feasible, R, (geom.tension_min, geom.tension_max), spacing)


def check_waypoints(geom: CdprGeometry, poses: list[np.ndarray]) -> None:
    """Every pose inside the frame and wrench-feasible within the geometry's tension limits.

    Raises:
        ValueError: naming the first bad pose (``waypoints[i]``, from 0) and the limits.
    """
    for i, T in enumerate(poses):
        where = f"waypoints[{i}] {vector_from_pose(T).round(4).tolist()}"
        geom.check_pose_inside(T, where)
        if not is_feasible(geom, T):
            raise ValueError(f"{where} {infeasible_reason(geom)}")


def infeasible_reason(geom: CdprGeometry) -> str:
    """Why a pose is not wrench-feasible, and the fix (for error messages)."""
    return (
        f"is outside the wrench-feasible workspace: no tension distribution with "
        f"{geom.tension_min:g} N ≤ τ ≤ {geom.tension_max:g} N holds the platform's "
        f"{geom.mass:g} kg there; choose a pose nearer the workspace centre "
        "(`cdpr-twin model workspace` draws it)"
    )
