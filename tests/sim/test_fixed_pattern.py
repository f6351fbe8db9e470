"""The sensor's fixed-pattern noise (PRNU, DSNU) against a flat-field calibration done here.

A camera's gain and offset maps are measured as EMVA 1288 measures them: average many frames of
a flat, static scene at two irradiances and solve, pixel by pixel, the line through the two
means. The recovered maps must be the drawn ones (to within the shot and read noise left in the
averages, predicted from the Poisson law) and have the stds asked for (to within their sampling
error); the maps belong to the robot, not the run.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import CameraRealism, OpticsRealism
from cdpr_twin.sim import imaging
from cdpr_twin.sim.onboard_camera import OnboardCamera

FW, READ = 10_000.0, 10.0  # the acrobot profile's full well and read noise [e-]
SHAPE = (48, 64)
LEVELS = (0.15, 0.75)  # two flat irradiances, fractions of the full well (no clipping)
FRAMES = 400


def _mean_frame(level: float, pattern, rng: np.random.Generator) -> np.ndarray:
    """The mean of FRAMES noisy frames of a flat scene at ``level`` [DN]. (H, W)."""
    flat = np.full(SHAPE, level, np.float32)
    acc = np.zeros(SHAPE)
    for _ in range(FRAMES):
        acc += imaging.expose(flat, FW, READ, 1.0, rng, pattern)
    return acc / FRAMES


def _mean_var_dn(level: float, gain: np.ndarray) -> np.ndarray:
    """The variance of one pixel's FRAMES-frame mean [DN²]: Poisson + read, then 8-bit rounding."""
    e = gain * level * FW
    return ((255.0 / FW) ** 2 * (e + READ**2) + 1.0 / 12.0) / FRAMES


def test_flat_field_calibration_recovers_the_drawn_gain_and_offset_maps():
    prnu, dsnu = 0.01, 20.0
    gain, offset = imaging.fixed_pattern(SHAPE, prnu, dsnu, np.random.default_rng(7))
    rng = np.random.default_rng(1)
    (l1, l2) = LEVELS
    m1, m2 = (_mean_frame(level, (gain, offset), rng) for level in LEVELS)
    # the line DN = 255 (g·L·FW + d)/FW through the two means, per pixel
    g_hat = (m2 - m1) / (255.0 * (l2 - l1))
    d_hat = FW * (m1 / 255.0 - g_hat * l1)
    v1, v2 = _mean_var_dn(l1, gain), _mean_var_dn(l2, gain)
    var_g = (v1 + v2) / (255.0 * (l2 - l1)) ** 2
    var_d = (FW / 255.0) ** 2 * (l2**2 * v1 + l1**2 * v2) / (l2 - l1) ** 2
    n = gain.size
    # pixel by pixel, the recovered maps are the drawn ones to within the averages' noise: the
    # mean squared residual over n pixels has relative std √(2/n) (3.6 %); 5σ
    for est, truth, var in ((g_hat, gain, var_g), (d_hat, offset, var_d)):
        ratio = np.mean((est - truth) ** 2) / np.mean(var)
        assert abs(ratio - 1.0) < 5.0 * math.sqrt(2.0 / n), ratio
    # and their spreads are the magnitudes asked for: the recovered variance less the
    # estimation noise's, against σ², within the sample variance's sampling error (√(2/n) σ²,
    # plus the estimation noise's own, √(2/n)·var) at 5σ
    for est, sigma, var in ((g_hat, prnu, var_g), (d_hat, dsnu, var_d)):
        spread = np.var(est) - np.mean(var)
        tol = 5.0 * math.sqrt(2.0 / n) * (sigma**2 + np.mean(var))
        assert abs(spread - sigma**2) < tol, (math.sqrt(max(spread, 0.0)), sigma)


def test_a_pattern_of_unit_gains_and_zero_offsets_forms_the_frame_without_one():
    flat = np.random.default_rng(3).uniform(0.0, 1.0, SHAPE).astype(np.float32)
    none = imaging.expose(flat, FW, READ, 1 / 2.2, np.random.default_rng(5))
    unit = (np.ones(SHAPE, np.float32), np.zeros(SHAPE, np.float32))
    same = imaging.expose(flat, FW, READ, 1 / 2.2, np.random.default_rng(5), unit)
    assert np.array_equal(none, same)


def test_each_map_is_drawn_from_its_own_normals():
    # switching PRNU off leaves the DSNU map as it was (and the other way round)
    both = imaging.fixed_pattern(SHAPE, 0.01, 2.0, np.random.default_rng(4))
    dsnu_only = imaging.fixed_pattern(SHAPE, 0.0, 2.0, np.random.default_rng(4))
    prnu_only = imaging.fixed_pattern(SHAPE, 0.01, 0.0, np.random.default_rng(4))
    assert np.array_equal(both[1], dsnu_only[1]) and np.all(dsnu_only[0] == 1.0)
    assert np.array_equal(both[0], prnu_only[0]) and np.all(prnu_only[1] == 0.0)


@pytest.fixture(scope="module")
def twin():
    """Nominal robot, noise off; the cameras under test are built on its physics."""
    from cdpr_twin.sim import Twin

    with Twin(camera=False, tension_noise_std=0.0) as t:
        yield t


def _camera(twin, robot_seed: int, run_seed: int, **optics) -> OnboardCamera:
    r = CameraRealism(noise=True, full_well_e=FW, read_noise_e=READ)
    return OnboardCamera(
        twin.physics,
        twin.nominal.intrinsics,
        twin.nominal.tag_size,
        r,
        np.random.default_rng(robot_seed),
        np.random.default_rng(run_seed),
        optics=OpticsRealism(**optics),
    )


def test_the_pattern_is_the_robots_and_off_forms_the_old_frames(twin):
    fpn = {"prnu_std": 0.01, "dsnu_e": 2.0}
    cams = [
        _camera(twin, 11, 1, **fpn),
        _camera(twin, 11, 2, **fpn),
        _camera(twin, 12, 1, **fpn),
        _camera(twin, 11, 1),
    ]
    try:
        a, b, other, off = cams
        assert a._pattern is not None and b._pattern is not None and other._pattern is not None
        K = twin.nominal.intrinsics
        assert a._pattern[0].shape == (K.height, K.width)
        # same robot, another run: the same map; another robot: another map
        assert all(np.array_equal(p, q) for p, q in zip(a._pattern, b._pattern, strict=True))
        assert not np.array_equal(a._pattern[0], other._pattern[0])
        # the calibration is drawn from the robot's generator as without the pattern
        assert a.calibrated == off.calibrated
        frame_a, frame_off = a.render(), off.render()
        assert not np.array_equal(frame_a, frame_off)
        # off (the default), the frame is the one formed without the feature
        plain = OnboardCamera(
            twin.physics,
            twin.nominal.intrinsics,
            twin.nominal.tag_size,
            CameraRealism(noise=True, full_well_e=FW, read_noise_e=READ),
            np.random.default_rng(11),
            np.random.default_rng(1),
        )
        cams.append(plain)
        assert np.array_equal(plain.render(), frame_off)
    finally:
        for cam in cams:
            cam.close()


@pytest.mark.parametrize(("field", "value"), [("prnu_std", 0.5), ("dsnu_e", 5e3)])
def test_absurd_pattern_magnitudes_are_refused_in_one_line(field, value):
    with pytest.raises(OptionError) as err:
        OpticsRealism(**{field: value})
    message = str(err.value)
    assert field in message and "\n" not in message
