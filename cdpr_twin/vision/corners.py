"""Sub-pixel corners of a dark quad on a light background (the AprilTag's black square).

pupil-apriltags' quad fit is biased by up to 0.3 px on edges aligned with the pixel grid; the
refinement here fits a line to each edge's sub-pixel mid-level crossings and intersects them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np

__all__ = ["PixelMap", "refine_quad"]

PixelMap = Callable[[np.ndarray], np.ndarray]
"""A map of (n, 2) pixel coordinates to (n, 2) pixel coordinates."""


def _window(gray: np.ndarray, corners: np.ndarray, hw: float) -> tuple[np.ndarray, tuple]:
    """The part of the image the profiles sample, as float32, and its top-left pixel.

    The box around the corners grows by the profiles' half-length plus 2 px, so bilinear
    sampling (and OpenCV's border replication, at the image's own edges) sees exactly the
    pixels it would in the whole image: the profiles are bit-identical, at a fraction of the
    cost of converting the whole frame.
    """
    h, w = gray.shape
    pad = int(np.ceil(hw)) + 2
    lo = np.floor(corners.min(axis=0)).astype(int) - pad
    hi = np.ceil(corners.max(axis=0)).astype(int) + pad + 1
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), w), min(int(hi[1]), h)
    if x1 - x0 < 2 or y1 - y0 < 2:  # corners outside the image: the whole frame
        return gray.astype(np.float32), (0, 0)
    return gray[y0:y1, x0:x1].astype(np.float32), (x0, y0)


def _edge_line(
    window: tuple[np.ndarray, tuple[int, int]],
    p0: np.ndarray,
    p1: np.ndarray,
    edge_len: float,
    centre: np.ndarray,
    steps: np.ndarray,
    undistort: PixelMap | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Total-least-squares line (point, direction) through one edge's sub-pixel crossings.

    ``window`` is (float32 image part, its top-left pixel (x0, y0)); profiles across the edge
    p0 → p1 are sampled at ``steps`` [px] along its outward normal;
    the mid-level crossing of each is an edge point (mapped by ``undistort`` when given: the
    line is then fitted where edges are straight). ``None`` with fewer than 4 points.
    """
    d = (p1 - p0) / edge_len
    n = np.array([-d[1], d[0]])
    if n @ ((p0 + p1) / 2 - centre) < 0:
        n = -n  # outward normal: dark inside, light outside
    ts = np.linspace(0.15, 0.85, max(8, int(edge_len / 2)))
    base = p0 + ts[:, None] * (p1 - p0)
    pts = base[:, None, :] + steps[None, :, None] * n  # (k, s, 2)
    img, (x0, y0) = window
    prof = cv2.remap(
        img,
        pts[..., 0].astype(np.float32) - np.float32(x0),  # exact: integer shifts of float32
        pts[..., 1].astype(np.float32) - np.float32(y0),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    # (ufunc reductions: the same values as .min/.max/.mean, without their Python wrappers)
    lo = np.minimum.reduce(prof, axis=1, keepdims=True)
    hi = np.maximum.reduce(prof, axis=1, keepdims=True)
    ok = (hi - lo).ravel() > 20.0
    f = prof - 0.5 * (lo + hi)  # rising from dark (inside) to light (outside)
    cross = (f[:, :-1] < 0) & (f[:, 1:] >= 0)
    rows = (ok & (cross.sum(axis=1) == 1)).nonzero()[0]  # profiles with one clean crossing
    if len(rows) < 4:
        return None
    i = cross[rows].argmax(axis=1)
    fi, fj = f[rows, i], f[rows, i + 1]
    t = steps[i] + (steps[i + 1] - steps[i]) * fi / (fi - fj)
    found = base[rows] + t[:, None] * n
    q = found if undistort is None else undistort(found)
    mean = np.add.reduce(q, axis=0) / len(q)
    # the total-least-squares direction: the major axis of the points' 2 × 2 scatter, whose
    # angle has a closed form (the first right singular vector of q − mean, up to its sign)
    (sxx, sxy), (_, syy) = ((q - mean).T @ (q - mean)).tolist()
    angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    return mean, np.array([math.cos(angle), math.sin(angle)])


def refine_quad(
    gray: np.ndarray,
    corners: np.ndarray,
    half_width: float = 3.0,
    undistort: PixelMap | None = None,
) -> np.ndarray:
    """Sub-pixel refinement of a dark quad's corners on a light background.

    Along each edge, the intensity profile across the edge is sampled (bilinear) at points
    between 15 % and 85 % of its length; the mid-level crossing of each profile is an edge point
    (exact for an area-sampled step edge). A line fitted to each edge's points (total least
    squares) is intersected with its neighbours'.

    Args:
        gray: (H, W) uint8 image.
        corners: (4, 2) corners in order around the quad [px, OpenCV convention].
        half_width: half-length of the profiles [px]; capped at 30 % of the shortest edge
            divided by 8 (one AprilTag border cell is 1/8 of the edge).
        undistort: the lens's undistortion (:func:`undistort_pixels`), applied to the edge
            points before the line fits; ``None`` for a pinhole.

    Returns:
        (4, 2) refined corners (undistorted with ``undistort``), or the input corners (also
        undistorted) when refinement is not possible.
    """
    c = np.asarray(corners, dtype=float)
    fallback = c if undistort is None else undistort(c)
    edge_len = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
    hw = min(half_width, 0.3 * edge_len.min() / 8.0)
    if hw < 1.0:
        return fallback
    centre = c.mean(axis=0)
    steps = np.linspace(-hw, hw, round(8 * hw) + 1)
    window = _window(gray, c, hw)
    lines = []
    for j in range(4):
        line = _edge_line(window, c[j], c[(j + 1) % 4], edge_len[j], centre, steps, undistort)
        if line is None:
            return fallback
        lines.append(line)
    out = np.empty((4, 2))
    for j in range(4):  # corner j is the meeting point of edges j-1 and j
        (m0, d0), (m1, d1) = lines[j - 1], lines[j]
        # m0 + s·d0 = m1 + u·d1, by Cramer's rule: det [d0, −d1] is the sine of their angle
        det = d1[0] * d0[1] - d0[0] * d1[1]
        if abs(det) < 1e-6:
            return fallback
        gap = m1 - m0
        s = (d1[0] * gap[1] - gap[0] * d1[1]) / det
        out[j] = m0 + s * d0
    if np.max(np.abs(out - fallback)) > 2.0:  # refinement wandered off: the detector's corners
        return fallback
    return out
