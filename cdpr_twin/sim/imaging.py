"""Image formation of a real camera from ideal renders (numpy and OpenCV, no MuJoCo).

The renderer gives what an ideal pinhole sees at one instant, its 8-bit values being the
display-encoded scene radiance (``DN = 255 · L^γ``, L the linear radiance in 0…1, γ the encoding
gamma of :class:`~cdpr_twin.robot.realism.CameraRealism`). A real camera's frame is made from such
renders the way the light reaches the sensor:

1. :func:`linear_luminance`: back to linear light, as a monochrome sensor sees it (Rec. 601
   luminance weights, the same as the detector's RGB → gray conversion);
2. :func:`average`: motion blur, the mean of sub-frames rendered during the exposure;
3. :func:`distort`: the lens, a Brown–Conrady distortion applied by a remap;
4. :func:`expose`: photo-electrons with shot and read noise, the encoding gamma and 8-bit
   quantisation (or :func:`encode` for a noise-free sensor); each pixel's own gain and dark
   offset (:func:`fixed_pattern`, the sensor's fixed-pattern noise) act on its electrons.

Pixel coordinates follow OpenCV (the centre of the top-left pixel is (0, 0)).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import CameraRealism
from cdpr_twin.types import CameraIntrinsics

LUMA = (0.299, 0.587, 0.114)
"""Rec. 601 luminance weights of R, G, B (OpenCV's ``COLOR_RGB2GRAY``)."""

POISSON_EXACT_BELOW = 1000.0
"""Mean electron count below which shot noise is drawn from the Poisson law itself [e⁻].

Above it the Poisson law is drawn from its normal limit (same mean and variance; skewness
1/√N < 3 %), which costs a tenth of exact draws over a whole frame.
"""


def linear_luminance(frame: np.ndarray, gamma: float) -> np.ndarray:
    """Linear luminance of a display-encoded render.

    Args:
        frame: (H, W, 3) RGB uint8 render, ``DN = 255 · L^γ`` per channel.
        gamma: the encoding gamma γ.

    Returns:
        (H, W) float32 linear luminance in 0…1.
    """
    lut = ((np.arange(256) / 255.0) ** (1.0 / gamma)).astype(np.float32)
    linear = cv2.LUT(frame, lut)
    return cv2.cvtColor(linear, cv2.COLOR_RGB2GRAY)


def average(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Mean of linear sub-frames: what the sensor integrates over the exposure.

    Args:
        frames: N (H, W) float32 linear images.

    Returns:
        (H, W) float32 mean.
    """
    out = frames[0].copy()
    for f in frames[1:]:
        out += f
    if len(frames) > 1:
        out *= np.float32(1.0 / len(frames))
    return out


def encode(linear: np.ndarray, gamma: float, in_place: bool = False) -> np.ndarray:
    """8-bit values of a noise-free linear image: ``round(255 · L^γ)``.

    Args:
        linear: (H, W) linear luminance (clipped to 0…1).
        gamma: the encoding gamma γ.
        in_place: ``linear`` is float32 scratch the function may overwrite (no copies).

    Returns:
        (H, W) uint8.
    """
    if in_place and linear.dtype == np.float32:
        x = np.clip(linear, 0.0, 1.0, out=linear)
    else:
        x = np.clip(linear, 0.0, 1.0, dtype=np.float32)
    if gamma != 1.0:
        x = cv2.pow(x, gamma)
    x *= np.float32(255.0)
    return np.rint(x, out=x).astype(np.uint8)


def expose(
    linear: np.ndarray,
    full_well_e: float,
    read_noise_e: float,
    gamma: float,
    rng: np.random.Generator,
    pattern: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """A noisy 8-bit frame: photo-electrons, shot and read noise, gamma, quantisation.

    Each pixel collects ``e = g · L · full_well_e`` electrons on average (L = 1 fills the well:
    the render's brightest level saturates; g its gain, 1 without a ``pattern``), draws shot
    noise (Poisson; its normal limit above :data:`POISSON_EXACT_BELOW`), adds its dark offset
    d and Gaussian read noise, and is read out as ``round(255 · clip(e'/full_well_e, 0, 1)^γ)``.
    Its std is then, to first order, ``σ_DN² = (dDN/de)² (e + read²) + 1/12`` (the last term:
    8-bit rounding), its mean ``255 · ((g·L·FW + d)/FW)^γ``.

    Args:
        linear: (H, W) float32 linear luminance in 0…1.
        full_well_e: electrons at full scale [e⁻].
        read_noise_e: read-noise std [e⁻].
        gamma: the encoding gamma γ.
        rng: the run's generator (it draws the Poisson counts, and seeds OpenCV's generator
            for the normal ones).
        pattern: the sensor's fixed pattern, (H, W) float32 gains g and (H, W) float32 dark
            offsets d [e⁻] (:func:`fixed_pattern`); ``None``: every pixel alike.

    Returns:
        (H, W) uint8.
    """
    fw = np.float32(full_well_e)
    e = np.clip(linear, 0.0, 1.0, dtype=np.float32)
    e *= fw
    if pattern is not None:
        # the pixel's gain scales its photo-electrons, and so their shot noise
        e *= pattern[0]
    z = np.empty(e.shape, np.float32)
    cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))  # OpenCV's normal draws: 3× numpy's speed
    # (OpenCV's stubs omit the scalar form of mean and stddev, which it documents)
    cv2.randn(z, 0.0, 1.0)  # type: ignore[call-overload]
    out = np.add(e, np.float32(read_noise_e**2))  # e + σ_r², then in place: e + √(e + σ_r²)·z
    np.sqrt(out, out=out)
    out *= z
    out += e
    low = e < POISSON_EXACT_BELOW
    if low.any():  # exact Poisson draws; z, independent of them, is the read noise there
        out[low] = rng.poisson(e[low]).astype(np.float32) + np.float32(read_noise_e) * z[low]
    if pattern is not None:
        # the dark offset adds to the charge before it is read out (and rounded)
        out += pattern[1]
    out *= np.float32(1.0) / fw
    return encode(out, gamma, in_place=True)


def fixed_pattern(
    shape: tuple[int, int], prnu_std: float, dsnu_e: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's fixed-pattern noise: each pixel's gain and dark offset, drawn once.

    Two (H, W) standard normal fields z₁, z₂ are drawn, in that order, whatever the
    magnitudes (a map stays the same when the other is switched off): gains
    ``g = 1 + prnu_std · z₁`` (EMVA 1288's PRNU, a relative std) and dark offsets
    ``d = dsnu_e · z₂`` [e⁻] (its DSNU), about the black level the sensor's clamp subtracts.

    Args:
        shape: (H, W) of the sensor.
        prnu_std: relative std of the gains.
        dsnu_e: std of the dark offsets [e⁻].
        rng: the robot's generator (a sensor's pattern is its own, the same in every run).

    Returns:
        (H, W) float32 gains and (H, W) float32 offsets [e⁻].
    """
    z = rng.standard_normal((2, *shape))
    gain = (1.0 + prnu_std * z[0]).astype(np.float32)
    return gain, (dsnu_e * z[1]).astype(np.float32)


def apply_pattern(
    linear: np.ndarray, pattern: tuple[np.ndarray, np.ndarray], full_well_e: float
) -> np.ndarray:
    """A noise-free sensor's mean signal with its fixed pattern: ``g·L + d/FW`` (0…1 scale).

    Args:
        linear: (H, W) float32 linear luminance (the fraction of the full well).
        pattern: gains and offsets [e⁻] (:func:`fixed_pattern`).
        full_well_e: electrons at full scale [e⁻].

    Returns:
        (H, W) float32.
    """
    out = np.clip(linear, 0.0, 1.0, dtype=np.float32)
    out *= pattern[0]
    out += pattern[1] * np.float32(1.0 / full_well_e)
    return out


def jpeg(gray: np.ndarray, quality: int) -> np.ndarray:
    """A frame as a JPEG encoder delivers it: compressed at an IJG quality, then decoded.

    Baseline JPEG (OpenCV's libjpeg): 8 × 8 blocks, each one's DCT coefficients rounded to
    multiples of the IJG luminance table scaled by the quality.

    Args:
        gray: (H, W) uint8 frame.
        quality: IJG quality 1–100.

    Returns:
        (H, W) uint8, the decoded frame.
    """
    ok, data = cv2.imencode(".jpg", gray, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError(f"realism.optics.jpeg_quality: OpenCV could not encode at {quality}")
    decoded = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    if decoded is None:
        raise ValueError(f"realism.optics.jpeg_quality: OpenCV could not decode at {quality}")
    return decoded


def distort_normalized(xy: np.ndarray, coeffs: Sequence[float]) -> np.ndarray:
    """Brown–Conrady distortion of normalized image coordinates (OpenCV's model).

    Args:
        xy: (..., 2) ideal normalized coordinates (x/z, y/z).
        coeffs: (k1, k2, p1, p2).

    Returns:
        (..., 2) distorted normalized coordinates.
    """
    k1, k2, p1, p2 = (float(c) for c in coeffs)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + k2 * r2)
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort_normalized(
    xy_d: np.ndarray, coeffs: Sequence[float], tol: float = 1e-12, max_iter: int = 200
) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort_normalized` by fixed-point iteration.

    Args:
        xy_d: (..., 2) distorted normalized coordinates.
        coeffs: (k1, k2, p1, p2).
        tol: stop when no point moves more than this (normalized units).
        max_iter: iteration limit.

    Returns:
        (..., 2) ideal normalized coordinates, and a (...) bool mask of the points whose
        inverse converged to a true pre-image (residual < 1e-9; strong barrel distortion
        folds the outer field, whose points have none).
    """
    k1, k2, p1, p2 = (float(c) for c in coeffs)
    xy = xy_d.copy()
    for _ in range(max_iter):
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + k2 * r2)
        tx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        ty = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        new = np.stack([(xy_d[..., 0] - tx) / radial, (xy_d[..., 1] - ty) / radial], axis=-1)
        new = np.where(np.isfinite(new), new, xy)
        step = np.max(np.abs(new - xy)) if new.size else 0.0
        xy = new
        if step < tol:
            break
    ok = np.linalg.norm(distort_normalized(xy, coeffs) - xy_d, axis=-1) < 1e-9
    return xy, ok


def lens_margins(
    intrinsics: CameraIntrinsics, coeffs: Sequence[float], limit: float = 0.5
) -> tuple[int, int]:
    """How far the ideal render must reach beyond the sensor's field for a distorting lens.

    A barrel lens (k1 < 0) images onto the sensor's edges scene points that an ideal pinhole
    with the same intrinsics sees *outside* its frame. A real camera shows them; a render of
    the sensor's own field alone would leave the distorted frame's edges black. This gives the
    margins, each side, of the ideal render (the *canvas*: the same focal length and pixel
    grid, the principal point shifted by the margins) that hold the pre-image of every pixel
    the remap samples, bilinear neighbours included.

    The pre-image of the field is bounded by that of its border (the lens's radial map is
    monotonic wherever it has an inverse), so the border's pixel centres are undistorted. A
    lens strong enough to fold its outer field gives some pixels no pre-image: those stay
    black, as they would through such a lens, and the others of the whole frame are searched.

    Args:
        intrinsics: the render's pinhole intrinsics (supersampled, if it is).
        coeffs: the lens's true (k1, k2, p1, p2).
        limit: the largest margin, as a fraction of the frame's side (a stronger lens keeps a
            black rim beyond it rather than render a huge canvas).

    Returns:
        (mx, my): whole pixels of canvas to add left and right, top and bottom (0, 0 for a
        pinhole or a pincushion lens).
    """
    K = intrinsics
    if not any(coeffs):
        return 0, 0
    us, vs = np.arange(K.width, dtype=float), np.arange(K.height, dtype=float)
    border = np.concatenate(
        [
            np.column_stack([us, np.zeros_like(us)]),
            np.column_stack([us, np.full_like(us, K.height - 1.0)]),
            np.column_stack([np.zeros_like(vs), vs]),
            np.column_stack([np.full_like(vs, K.width - 1.0), vs]),
        ]
    )
    x, y, ok = _preimage_pixels(K, coeffs, border[:, 0], border[:, 1])
    if not ok.all():  # a folding lens: the frame's pre-image is bounded inside, seek it there
        u, v = np.meshgrid(us, vs)
        x, y, ok = _preimage_pixels(K, coeffs, u.ravel(), v.ravel())
    if not ok.any():
        return 0, 0
    x, y = x[ok], y[ok]
    # bilinear sampling at x reads pixels floor(x) and floor(x) + 1; one more for the
    # fixed-point tables' rounding (1/32 px)
    need_x = max(0.0, -x.min(), x.max() - (K.width - 1.0)) + 1.0
    need_y = max(0.0, -y.min(), y.max() - (K.height - 1.0)) + 1.0
    mx = min(math.ceil(need_x), math.floor(limit * K.width))
    my = min(math.ceil(need_y), math.floor(limit * K.height))
    return (mx, my) if need_x > 1.0 or need_y > 1.0 else (0, 0)


def _preimage_pixels(
    K: CameraIntrinsics, coeffs: Sequence[float], u: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ideal pinhole pixels ``K · undistort(K⁻¹ (u, v))`` of distorted pixels, and which exist."""
    xy_d = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy], axis=-1)
    xy, ok = undistort_normalized(xy_d, coeffs)
    return K.fx * xy[..., 0] + K.cx, K.fy * xy[..., 1] + K.cy, ok


def distortion_maps(
    intrinsics: CameraIntrinsics, coeffs: Sequence[float], margins: tuple[int, int] = (0, 0)
) -> tuple[np.ndarray, np.ndarray]:
    """Remap tables of a lens with Brown–Conrady distortion, for :func:`distort`.

    Each pixel (u, v) of the distorted frame sees the scene point whose ideal pinhole pixel is
    ``K · undistort(K⁻¹ (u, v))``, with the *true* intrinsics K (the render's), read from an
    ideal render that reaches ``margins`` beyond the frame on each side (:func:`lens_margins`).

    Args:
        intrinsics: the pinhole intrinsics of the frame (and of the render, but its margins).
        coeffs: the lens's true (k1, k2, p1, p2).
        margins: (mx, my) pixels the render has beyond the frame left and right, top and
            bottom: its pixel (u + mx, v + my) is the frame's ideal pixel (u, v).

    Returns:
        Two (H, W) fixed-point maps for ``cv2.remap`` into the render (pixels with no pre-image
        map outside it, so they read black).
    """
    K = intrinsics
    u, v = np.meshgrid(np.arange(K.width, dtype=float), np.arange(K.height, dtype=float))
    x, y, ok = _preimage_pixels(K, coeffs, u, v)
    mx, my = margins
    map_x = np.where(ok, x + mx, -10.0).astype(np.float32)
    map_y = np.where(ok, y + my, -10.0).astype(np.float32)
    return cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)


def distort(linear: np.ndarray, maps: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The frame the distorting lens forms from an ideal pinhole image (bilinear sampling).

    Args:
        linear: (H, W) float32 linear image of the ideal pinhole.
        maps: from :func:`distortion_maps`.

    Returns:
        (H, W) float32; what falls outside the rendered field of view is black.
    """
    return cv2.remap(
        linear, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    )


def integrate_pixels(linear: np.ndarray, factor: int) -> np.ndarray:
    """What each sensor pixel collects: the mean of its ``factor`` × ``factor`` samples.

    A pixel integrates the light over its area; rendering ``factor`` times finer and averaging
    blocks is that integral by the midpoint rule (a point-sampled render aliases edges narrower
    than a pixel, which biases sub-pixel corner fits).

    Args:
        linear: (H·factor, W·factor) float32 linear image.
        factor: samples per pixel along each axis.

    Returns:
        (H, W) float32.
    """
    h, w = linear.shape[0] // factor, linear.shape[1] // factor
    return cv2.resize(linear, (w, h), interpolation=cv2.INTER_AREA)


def subframe_offsets(exposure_s: float, n: int) -> np.ndarray:
    """How long before the end of the exposure each sub-frame is taken [s].

    Sub-frame i (0…n−1) is at the centre of the i-th of n equal slices of the exposure
    [t − exposure, t]: ``exposure · (1 − (i + 0.5)/n)`` before t. Returns (n,).
    """
    return exposure_s * (1.0 - (np.arange(n) + 0.5) / n)


def check_exposure(r: CameraRealism, period: float | None, timestep: float) -> None:
    """Refuse an exposure longer than the read period, or more sub-frames than it has steps.

    Raises:
        OptionError: naming ``realism.camera.exposure_s`` or ``blur_subframes``.
    """
    if r.exposure_s > 0 and not (period is not None and r.exposure_s <= period):
        raise OptionError(
            "realism.camera.exposure_s",
            f"{r.exposure_s:g} s needs the camera's read period (got {period}) and must not "
            "exceed it",
        )
    steps = max(math.floor(r.exposure_s / timestep + 1e-9), 1)  # distinct states exposed
    if r.exposure_s > 0 and r.blur_subframes > steps:
        raise OptionError(
            "realism.camera.blur_subframes",
            f"{r.blur_subframes} sub-frames in a {r.exposure_s:g} s exposure: at most {steps}, "
            f"one per physics step of {timestep:g} s (more would render the same state again)",
        )
