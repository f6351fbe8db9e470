"""The lens and the light: defocus, vignetting, flicker, rolling shutter (numpy and OpenCV).

Each function acts on the linear image of :mod:`cdpr_twin.sim.imaging` (float32, 0…1, pixel
coordinates as OpenCV's) or says how rows are exposed:

- :func:`blur_circle_px`: the thin lens's circle of confusion for a point at one depth, when
  the lens is focused at another; :func:`defocus` blurs the frame by it with the geometric
  point-spread function of an out-of-focus lens, a uniform disk (pillbox) whose diameter is
  that circle (:func:`disk_kernel`). Its edge-spread function is :func:`disk_edge_spread`.
- :func:`vignetting_map`: the natural fall-off of illumination off the optical axis, cos⁴θ
  (θ the angle of the pixel's ray).
- :func:`flicker_gain`: the mean over each exposure window of lighting modulated at the mains'
  second harmonic, 1 + m·sin(2π f t + φ).
- :func:`row_weights`: a rolling shutter exposes row r over [e_r − E, e_r], e_r = t_end −
  (H − 1 − r)·t_line (the last row read out at t_end): the weights of sub-frames rendered at
  given times that reproduce each row's exposure (linear interpolation in time between
  sub-frames, integrated over the row's window).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from cdpr_twin.types import CameraIntrinsics

KERNEL_SAMPLES = 16
"""Samples per pixel side when a pixel's share of the blur disk is integrated: the area of a
disk's edge within a pixel is then right to ≈ 1/16² of a pixel."""


MAX_BLUR_PX = 100.0
"""The widest circle of confusion applied [px]: a frame blurred by more shows no tag."""


def blur_circle_px(
    depth: float, focus: float, focal_length: float, f_number: float, focal_px: float
) -> float:
    """The thin lens's circle of confusion for a point ``depth`` away, in pixels.

    c = A·f·|s − s_f| / (s·(s_f − f)) on the sensor, A = f/N the aperture's diameter, s the
    point's distance and s_f the focus distance along the axis; a pixel is f/f_px wide.

    Args:
        depth: the point's distance along the optical axis s [m].
        focus: the distance the lens is focused at s_f [m] (> f).
        focal_length: the lens's focal length f [m].
        f_number: N.
        focal_px: the focal length in pixels f_px.

    Returns:
        The circle's diameter [px].
    """
    aperture = focal_length / f_number
    on_sensor = aperture * focal_length * abs(depth - focus) / (depth * (focus - focal_length))
    return on_sensor * focal_px / focal_length


@functools.lru_cache(maxsize=64)
def disk_kernel(diameter_px: float) -> np.ndarray:
    """The pillbox PSF of a ``diameter_px`` circle on the pixel grid: each pixel's area share.

    Returns:
        (k, k) float32 kernel summing to 1, k odd (a single 1 below a tenth of a pixel).
    """
    radius = 0.5 * diameter_px
    if radius < 0.05:
        return np.ones((1, 1), np.float32)
    half = math.ceil(radius + 0.5)
    n = KERNEL_SAMPLES
    # sample points at the centres of n × n sub-cells of each pixel
    offsets = (np.arange(n) + 0.5) / n - 0.5
    grid = np.arange(-half, half + 1)
    fine = (grid[:, None] + offsets[None, :]).ravel()
    inside = (fine[:, None] ** 2 + fine[None, :] ** 2) <= radius**2
    k = 2 * half + 1
    area = inside.reshape(k, n, k, n).mean(axis=(1, 3))
    return (area / area.sum()).astype(np.float32)


def disk_edge_spread(x: np.ndarray, diameter: float) -> np.ndarray:
    """The edge-spread function of a uniform disk PSF: its share left of x (x from the edge).

    ESF(x) = 1/2 + (x·√(R² − x²) + R²·asin(x/R)) / (π R²) for |x| ≤ R, 0 or 1 beyond.

    Args:
        x: positions from the edge [px] (positive: the bright side).
        diameter: the disk's diameter 2R [px].
    """
    r = 0.5 * diameter
    u = np.clip(np.asarray(x, dtype=float), -r, r)
    return 0.5 + (u * np.sqrt(r * r - u * u) + r * r * np.arcsin(u / r)) / (math.pi * r * r)


def defocus(linear: np.ndarray, diameter_px: float) -> np.ndarray:
    """The frame seen through a lens defocused to a ``diameter_px`` circle of confusion.

    Args:
        linear: (H, W) float32 linear image.
        diameter_px: the circle of confusion [px].

    Returns:
        (H, W) float32 (the image itself below a tenth of a pixel).
    """
    # (a circle wider than MAX_BLUR_PX leaves no image to speak of: it is held there)
    kernel = disk_kernel(round(min(float(diameter_px), MAX_BLUR_PX), 2))
    if kernel.shape == (1, 1):
        return linear
    # (the frame's edge repeats its border pixels: the lens saw beyond it, much like them)
    return cv2.filter2D(linear, -1, kernel, borderType=cv2.BORDER_REPLICATE)


def vignetting_map(K: CameraIntrinsics, power: float) -> np.ndarray:
    """The relative illumination of each pixel, cos^power θ (θ its ray's angle to the axis).

    Args:
        K: the true intrinsics of the frame.
        power: 4 for a thin lens's natural vignetting (the cos⁴ law).

    Returns:
        (H, W) float32, 1 on the optical axis.
    """
    u = (np.arange(K.width) - K.cx) / K.fx
    v = (np.arange(K.height) - K.cy) / K.fy
    cos2 = 1.0 / (1.0 + u[None, :] ** 2 + v[:, None] ** 2)
    return (cos2 ** (0.5 * power)).astype(np.float32)


def flicker_gain(
    ends: np.ndarray, exposure: float, frequency: float, depth: float, phase: float
) -> np.ndarray:
    """The mean light over exposures ending at ``ends`` under 1 + m·sin(2π f t + φ).

    Over [t − E, t]: 1 + m·(cos(ω(t − E) + φ) − cos(ωt + φ))/(ωE); with E = 0, the light at t.

    Args:
        ends: the exposures' end times [s] (one per row for a rolling shutter).
        exposure: E [s].
        frequency: f [Hz] (twice the mains' frequency for lamps on AC).
        depth: m, the modulation's relative amplitude.
        phase: φ [rad].
    """
    w = 2.0 * math.pi * frequency
    t = np.asarray(ends, dtype=float)
    if exposure == 0.0:
        return 1.0 + depth * np.sin(w * t + phase)
    return 1.0 + depth * (np.cos(w * (t - exposure) + phase) - np.cos(w * t + phase)) / (
        w * exposure
    )


def row_weights(
    times: np.ndarray,
    rows: np.ndarray,
    height: int,
    t_end: float,
    exposure: float,
    t_line: float,
) -> np.ndarray:
    """Weights of sub-frames rendered at ``times`` that form each row of a rolling shutter.

    Sensor row r (0 at the top, read first) is exposed over [e_r − E, e_r], e_r = t_end −
    (H − 1 − r)·t_line. Between two sub-frames the scene is taken to change linearly in time
    (each pixel's light interpolated), so a row's weight on sub-frame k is the mean over its
    window of the hat function of ``times`` at k (with E = 0, its value at e_r). Times outside
    the rendered span take the nearest sub-frame.

    Args:
        times: (K,) increasing sub-frame times [s].
        rows: (n,) the sensor rows (fractional: a finer or wider render's rows) to weigh;
            rows beyond the sensor's take its first or last row's time.
        height: H, the sensor's rows.
        t_end: when the last row's exposure ends [s].
        exposure: E [s].
        t_line: the row-to-row delay [s].

    Returns:
        (n, K) float32 weights, each row summing to 1.
    """
    times = np.asarray(times, dtype=float)
    r = np.clip(np.asarray(rows, dtype=float), 0.0, height - 1.0)
    ends = t_end - (height - 1.0 - r) * t_line
    eye = np.eye(times.size)
    if exposure == 0.0:
        w = np.stack([np.interp(ends, times, eye[k]) for k in range(times.size)], axis=1)
        return w.astype(np.float32)
    # the mean of each piecewise-linear hat over [e − E, e]: the difference of its integral
    # (beyond the rendered span the hat is constant: its integral goes on linearly)
    lo, hi = min(times[0], (ends - exposure).min()) - 1.0, max(times[-1], ends.max()) + 1.0
    grid = np.concatenate([[lo], times, [hi]])
    columns: list[np.ndarray] = []
    for k in range(times.size):
        hat = np.interp(grid, times, eye[k])
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (hat[1:] + hat[:-1]) * np.diff(grid))])
        # the integral is piecewise quadratic: interpolate it exactly by sub-sampling each
        # segment's hat linearly (np.interp of cum alone would be off inside a segment)
        columns.append(
            (_hat_integral(grid, hat, cum, ends) - _hat_integral(grid, hat, cum, ends - exposure))
            / exposure
        )
    return np.stack(columns, axis=1).astype(np.float32)


def _hat_integral(grid: np.ndarray, hat: np.ndarray, cum: np.ndarray, t: np.ndarray) -> np.ndarray:
    """∫ from grid[0] to t of the piecewise-linear ``hat`` (its values at ``grid``)."""
    i = np.clip(np.searchsorted(grid, t, side="right") - 1, 0, grid.size - 2)
    dt = t - grid[i]
    slope = (hat[i + 1] - hat[i]) / (grid[i + 1] - grid[i])
    return cum[i] + hat[i] * dt + 0.5 * slope * dt * dt
