"""The camera's calibration errors, drawn over many robots, against the stated statistics.

The expected values are the profile's stated correlations and stds, and closed forms of them
(the aspect ratio's std); the tolerance is the sampling error of a correlation estimated from
n robots, (1 − ρ²)/√n (Fisher), taken five times.
"""

import numpy as np

from cdpr_twin.robot.realism import profile
from cdpr_twin.sim.onboard_camera import calibrate
from cdpr_twin.types import CameraIntrinsics

K = CameraIntrinsics(640, 480, 415.69, 415.69, 319.5, 239.5)
N_ROBOTS = 4000


def _errors(name: str) -> np.ndarray:
    """(N_ROBOTS, 8) errors of (fx/f − 1, fy/f − 1, cx, cy, k1, k2, p1, p2), one robot a row."""
    r = profile(name)
    rows = []
    for seed in range(N_ROBOTS):
        cal, dist = calibrate(K, r.camera, np.random.default_rng(seed), r.optics)
        lens = np.subtract(dist, r.camera.distortion)
        rows.append([cal.fx / K.fx - 1, cal.fy / K.fy - 1, cal.cx - K.cx, cal.cy - K.cy, *lens])
    return np.array(rows)


def _tolerance(rho: float) -> float:
    return 5.0 * (1.0 - rho**2) / np.sqrt(N_ROBOTS)


def test_full_profile_draws_errors_with_a_calibrations_correlations():
    r = profile("acrobot_full")
    e = _errors("acrobot_full")
    corr = np.corrcoef(e.T)
    stated = r.optics.calibration_correlation()
    for i, j in [(0, 1), (4, 5), (2, 7), (3, 6), (0, 4), (1, 2), (5, 6)]:
        assert abs(corr[i, j] - stated[i, j]) < _tolerance(stated[i, j]), (i, j, corr[i, j])
    # each error keeps the camera's own std (std of a std estimate: σ/√(2n))
    std = [r.camera.focal_error_std] * 2 + [r.camera.center_error_std_px] * 2
    std += list(r.camera.distortion_error_std)
    assert np.allclose(e.std(axis=0), std, rtol=5.0 / np.sqrt(2 * N_ROBOTS))
    # fy/fx is pinned: its relative error has std σ_f·√(2(1 − ρ)) (to first order in σ_f)
    aspect = (1 + e[:, 1]) / (1 + e[:, 0]) - 1
    sigma = r.camera.focal_error_std * np.sqrt(2 * (1 - r.optics.focal_correlation))
    assert abs(aspect.std() / sigma - 1) < 5.0 / np.sqrt(2 * N_ROBOTS) + 0.01
    assert aspect.std() < 0.25 * r.camera.focal_error_std


def test_acrobot_profile_keeps_independent_draws_in_their_order():
    r = profile("acrobot")
    rng = np.random.default_rng(7)
    df = rng.normal(0.0, r.camera.focal_error_std, 2)
    dc = rng.normal(0.0, r.camera.center_error_std_px, 2)
    dd = rng.normal(0.0, np.asarray(r.camera.distortion_error_std))
    cal, dist = calibrate(K, r.camera, np.random.default_rng(7), r.optics)
    assert (cal.fx, cal.fy, cal.cx, cal.cy) == (
        K.fx * (1 + df[0]),
        K.fy * (1 + df[1]),
        K.cx + dc[0],
        K.cy + dc[1],
    )
    assert dist == tuple(float(c) for c in np.asarray(r.camera.distortion) + dd)
    # independent: the aspect ratio is as loose as either focal length (σ√2)
    e = _errors("acrobot")
    assert abs(np.corrcoef(e[:, 0], e[:, 1])[0, 1]) < _tolerance(0.0)
