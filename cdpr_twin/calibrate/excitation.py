"""The excitation: static poses that make the calibration's unknowns visible (numpy + scipy).

Poses are drawn from scrambled Halton sequences — part in a box above the tag, from which the
onboard camera sees it, part spread through the workspace; rotations up to ``max_angle`` — and
kept when, in the *nominal* model, they are inside the frame,
wrench-feasible with every tension at least ``tension_margin`` above the robot's minimum (so
that the true robot, which differs, keeps its cables taut) and show the whole tag at least
``pixel_margin`` inside the image. They are then ordered as a short tour from the start pose.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import qmc

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import inverse, matrix_from_euler_xyz, pose_distance, transform
from cdpr_twin.math.workspace import inside_frame, is_feasible
from cdpr_twin.types import CameraIntrinsics
from cdpr_twin.vision.detection import inside_image, tag_pixels


def tag_in_view(
    geom: CdprGeometry,
    T_base_tag: np.ndarray,
    intrinsics: CameraIntrinsics,
    tag_size: float,
    T_base_platform: np.ndarray,
    pixel_margin: float = 40.0,
) -> bool:
    """Whether the nominal model sees the whole tag at a pose, ``pixel_margin`` inside."""
    T_cam_tag = inverse(geom.T_platform_cam) @ inverse(T_base_platform) @ T_base_tag
    if T_cam_tag[2, 3] <= 0.05 or T_cam_tag[2, 2] < 0.3:  # behind, or edge-on (z into the tag)
        return False
    uv, _ = tag_pixels(intrinsics, T_cam_tag, tag_size)
    return inside_image(intrinsics, uv, pixel_margin)


def _draw(
    geom: CdprGeometry, n: int, centre, half, max_angle: float, t_min: float, seed: int, keep
) -> list[np.ndarray]:
    """``n`` poses from a scrambled Halton sequence in a box that pass ``keep``."""
    if n <= 0:
        return []
    sampler = qmc.Halton(d=6, scramble=True, seed=seed)
    poses: list[np.ndarray] = []
    for _ in range(50):
        for u in sampler.random(max(4 * n, 32)):
            p = centre + (2.0 * u[:3] - 1.0) * half
            T = transform(matrix_from_euler_xyz((2.0 * u[3:] - 1.0) * max_angle), p)
            if inside_frame(geom, T) and keep(T) and is_feasible(geom, T, tension_min=t_min):
                poses.append(T)
                if len(poses) == n:
                    return poses
    return poses


def excitation_poses(
    geom: CdprGeometry,
    T_base_tag: np.ndarray,
    intrinsics: CameraIntrinsics,
    tag_size: float,
    n: int,
    start: np.ndarray,
    seed: int = 0,
    seen_fraction: float = 0.5,
    max_angle: float = math.radians(12.0),
    tension_margin: float = 1.0,
    pixel_margin: float = 40.0,
) -> list[np.ndarray]:
    """``n`` excitation poses, in the order to visit them from ``start``.

    A share ``seen_fraction`` of them lies in a box over the tag (±0.2 m, heights 0.08–0.45 m)
    and shows the tag; the others spread through the frame's lower half (±0.3 m, heights
    0.08–0.55 m), where their cable lengths constrain the exit points from other directions.

    Args:
        geom: the nominal geometry.
        T_base_tag: (4, 4) the nominal tag pose.
        intrinsics: the calibrated camera intrinsics.
        tag_size: the tag's edge [m].
        n: number of poses.
        start: (4, 4) where the robot starts (the tour begins there).
        seed: the Halton sequences' scrambling seed.
        seen_fraction: share of the poses that must show the tag.
        max_angle: largest rotation about each axis [rad].
        tension_margin: tension reserve above the robot's minimum [N].
        pixel_margin: the tag's distance from the image border [px].

    Raises:
        ValueError: when too few poses qualify (the tag is out of reach).
    """
    t_min = geom.tension_min + tension_margin
    n_seen = max(1, round(seen_fraction * n))
    tag = np.array([T_base_tag[0, 3], T_base_tag[1, 3], 0.265])
    seen = _draw(
        geom,
        n_seen,
        tag,
        np.array([0.2, 0.2, 0.185]),
        max_angle,
        t_min,
        seed,
        lambda T: tag_in_view(geom, T_base_tag, intrinsics, tag_size, T, pixel_margin),
    )
    if len(seen) < n_seen:
        raise ValueError(
            f"only {len(seen)} of {n_seen} excitation poses see the tag and keep the cables "
            "taut; ask for fewer poses, or check the tag and camera in the robot description"
        )
    wide = _draw(
        geom,
        n - n_seen,
        np.array([0.0, 0.0, 0.315]),
        np.array([0.3, 0.3, 0.235]),
        max_angle,
        t_min,
        seed + 1,
        lambda T: True,
    )
    return tour(seen + wide, start)


def tour(poses: list[np.ndarray], start: np.ndarray) -> list[np.ndarray]:
    """The poses ordered greedily, each next one the nearest (position + 0.2 m/rad)."""
    if not poses:
        return []
    T = np.asarray(poses, dtype=float)
    left, out, here = np.ones(len(T), dtype=bool), [], np.asarray(start, dtype=float)
    for _ in range(len(T)):
        dt, dr = pose_distance(here, T)
        j = int(np.argmin(np.where(left, dt + 0.2 * dr, np.inf)))
        left[j], here = False, T[j]
        out.append(poses[j])
    return out
