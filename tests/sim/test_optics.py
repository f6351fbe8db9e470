"""The lens and the light against closed forms derived here, not read from the code.

- defocus: a step edge blurred by the pillbox PSF has the edge-spread function of a uniform
  disk (the area of a circular segment, written here), its 10-90 % width solved from it;
- the circle of confusion from the thin-lens equation and similar triangles (the code uses
  the equivalent closed form in the object distances);
- vignetting: cos⁴ of each pixel's ray angle, from the ray's direction;
- flicker: the exposure's mean light by numerical quadrature;
- the camera applies them with the tag's true depth.
"""

import math

import numpy as np
import pytest
from conftest import paper_pose
from scipy.integrate import quad
from scipy.optimize import brentq

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import CameraRealism, OpticsRealism, profile
from cdpr_twin.sim import optics
from cdpr_twin.sim.onboard_camera import OnboardCamera
from cdpr_twin.types import CameraIntrinsics


def _segment_share(x, r):
    """The share of a disk of radius r left of a line x from its centre (circular segment)."""
    if x <= -r:
        return 0.0
    if x >= r:
        return 1.0
    d = -x  # the right-hand segment's distance from the centre
    segment = r * r * math.acos(d / r) - d * math.sqrt(r * r - d * d) if d > 0 else None
    if segment is None:  # the line is right of the centre: the left part is the big one
        d = x
        small = r * r * math.acos(d / r) - d * math.sqrt(r * r - d * d)
        return 1.0 - small / (math.pi * r * r)
    return segment / (math.pi * r * r)


@pytest.mark.parametrize("diameter", [2.6, 5.3])
def test_a_defocused_edge_has_the_disks_edge_spread_function(diameter):
    image = np.zeros((60, 60), np.float32)
    image[:, 30:] = 1.0  # a step at x = 29.5 (the boundary between columns 29 and 30)
    row = optics.defocus(image, diameter)[30]
    x = np.arange(60) - 29.5
    esf = np.array([_segment_share(v, diameter / 2) for v in x])
    # each pixel's share of the disk is integrated on 16 × 16 sub-cells: ≈ 1e-3 of the light
    assert np.abs(row - esf).max() < 3e-3
    # a disk 5 % wider or narrower is told apart (the check sees the blur's size)
    for other in (0.95 * diameter, 1.05 * diameter):
        wrong = np.array([_segment_share(v, other / 2) for v in x])
        assert np.abs(row - wrong).max() > 3 * 3e-3
    # the 10-90 % width, solved from the ESF: 0.69 of the circle's diameter, not the diameter
    lo = brentq(lambda v: _segment_share(v, diameter / 2) - 0.1, -diameter, diameter)
    hi = brentq(lambda v: _segment_share(v, diameter / 2) - 0.9, -diameter, diameter)
    assert (hi - lo) / diameter == pytest.approx(0.687, abs=0.001)


@pytest.mark.parametrize("depth", [0.09, 0.36])
def test_the_circle_of_confusion_is_the_thin_lenses(depth):
    f, n, focus, f_px = 3.04e-3, 2.0, 0.15, 415.69
    # thin lens 1/f = 1/s + 1/v: the sensor sits at v_f; a point at s focuses at v; the cone
    # of aperture A = f/N converging to v is |v − v_f|·A/v wide at the sensor
    v_f, v = 1 / (1 / f - 1 / focus), 1 / (1 / f - 1 / depth)
    c = (f / n) * abs(v - v_f) / v
    # a pixel is v_f/f_px on the sensor for a pinhole of the render's f_px at the image distance
    # v_f ≈ f (1 + f/s_f): the model's f_px is the lens's focal length over the pitch
    assert optics.blur_circle_px(depth, focus, f, n, f_px) == pytest.approx(
        c / (f / f_px), rel=1e-12
    )


def test_vignetting_is_cos4_of_the_rays_angle():
    K = CameraIntrinsics(640, 480, 415.69, 415.69, 319.5, 239.5)
    vig = optics.vignetting_map(K, 4.0)
    for u, v in [(0, 0), (639, 479), (319, 239), (100, 400)]:
        ray = np.array([(u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0])
        theta = math.acos(ray[2] / np.linalg.norm(ray))
        assert vig[v, u] == pytest.approx(math.cos(theta) ** 4, rel=1e-6)


def test_flicker_is_the_exposures_mean_light():
    f, m, phase, e = 100.0, 0.05, 0.7, 0.008
    for t in (0.04, 0.123, 1.0):
        mean = quad(lambda s: 1 + m * math.sin(2 * math.pi * f * s + phase), t - e, t)[0] / e
        assert optics.flicker_gain(t, e, f, m, phase) == pytest.approx(mean, rel=1e-12)


@pytest.fixture(scope="module")
def twin():
    from cdpr_twin.sim import Twin

    with Twin(camera=False, tension_noise_std=0.0) as t:
        yield t


def test_the_camera_defocuses_by_the_tags_true_depth(twin):
    twin.reset(paper_pose("p1"))
    lens = OpticsRealism(defocus=True, focus_distance=0.3)
    sharp_cam, blurred_cam = (
        OnboardCamera(
            twin.physics,
            twin.nominal.intrinsics,
            twin.nominal.tag_size,
            CameraRealism(supersample=2),  # a formed frame, no noise
            np.random.default_rng(0),
            np.random.default_rng(0),
            optics=o,
        )
        for o in (None, lens)
    )
    try:
        sharp, blurred = sharp_cam.render(), blurred_cam.render()
    finally:
        sharp_cam.close()
        blurred_cam.close()
    depth = twin.physics.T_cam_tag[2, 3]  # p1: the camera 9 cm above the tag
    c = optics.blur_circle_px(depth, 0.3, 3.04e-3, 2.0, 415.69)
    assert c > 3.0  # a visible blur: the check can fail
    linear = sharp[..., 0].astype(np.float32) / 255.0
    expected = np.round(255.0 * optics.defocus(linear, c))
    # the blur of the 8-bit sharp frame against the blur before quantisation: ≤ 1 DN
    assert np.abs(blurred[..., 0].astype(float) - expected).max() <= 1.0


def test_the_full_profile_has_the_lens_and_light_and_acrobot_not():
    assert profile("acrobot_full").optics.forms
    assert not profile("acrobot").optics.forms


def test_a_rolling_shutter_skews_a_moving_vertical_edge_by_v_t_line_per_row():
    height, t_line, exposure, v = 480, 3448 / 182.4e6, 0.008, 500.0  # v [px/s]
    span = exposure + (height - 1) * t_line
    times = np.linspace(-span, 0.0, 3)  # blur_subframes + 1 renders over the readout
    x = np.arange(200, dtype=float)

    def edge(t):  # a vertical edge, a 40 px linear ramp centred at 100 + v·t
        return np.clip((x - (100.0 + v * t)) / 40.0 + 0.5, 0.0, 1.0)

    w = optics.row_weights(times, np.arange(height), height, 0.0, exposure, t_line)
    assert np.allclose(w.sum(axis=1), 1.0, atol=1e-6)
    frame = w @ np.stack([edge(t) for t in times])
    # each row's edge where its light crosses one half (the ramp is linear there)
    crossing = np.array([np.interp(0.5, row, x) for row in frame])
    slope = np.polyfit(np.arange(height), crossing, 1)[0]
    assert slope == pytest.approx(v * t_line, rel=1e-4)
    # and the first row sits where the edge was at the middle of its own window
    first_mid = -(height - 1) * t_line - exposure / 2
    assert crossing[0] == pytest.approx(100.0 + v * first_mid, abs=1e-3)


def test_readout_and_exposure_must_fit_in_the_read_period(twin):
    with pytest.raises(OptionError, match=r"realism\.optics\.line_time"):
        OnboardCamera(
            twin.physics,
            twin.nominal.intrinsics,
            twin.nominal.tag_size,
            CameraRealism(exposure_s=0.008, blur_subframes=2),
            np.random.default_rng(0),
            np.random.default_rng(0),
            period=0.01,
            optics=OpticsRealism(line_time=2e-5),
        )


def test_vignetting_dims_the_inks_black_level_too(twin):
    """The lens dims all the light reaching a pixel: a black ink's reflection as much as white.

    A flat black scene with an ink reflecting ``b`` of the light, and a flat white one
    reflecting ``w``, form ``round(255·cos⁴θ·b)`` and ``round(255·cos⁴θ·w)`` (γ = 1, no noise),
    θ each pixel's ray angle computed here from the intrinsics; a black level added after the
    lens would stay ``b`` in the corners, 3.7 times the 0.27 of cos⁴ there.
    """
    b, w = 0.1, 0.8
    cam = OnboardCamera(
        twin.physics,
        twin.nominal.intrinsics,
        twin.nominal.tag_size,
        CameraRealism(noise=False, gamma=1.0, black_level=b, white_level=w),
        np.random.default_rng(0),
        np.random.default_rng(0),
        optics=OpticsRealism(vignetting_power=4.0),
    )
    K = cam.true_intrinsics
    v, u = np.mgrid[0 : K.height, 0 : K.width].astype(float)
    tan2 = ((u - K.cx) / K.fx) ** 2 + ((v - K.cy) / K.fy) ** 2
    cos4 = 1.0 / (1.0 + tan2) ** 2
    try:
        for level, reflect in ((0, b), (255, w)):
            render = np.full((K.height, K.width, 3), level, np.uint8)
            frame = cam._form([render])[..., 0].astype(float)
            assert np.abs(frame - np.round(255.0 * cos4 * reflect)).max() <= 1.0
    finally:
        cam.close()
