"""The windowed tag search against the whole-frame search, on the ``acrobot`` camera's frames.

The window (around the last detection) is a speed-up only: on the same noisy, blurred and
distorted frames it must find the tag exactly when the whole-frame search does, with corners and
poses equal to far below the detection's own noise, and it must fall back to the whole frame
when the tag leaves the window.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.math import se3
from cdpr_twin.robot.realism import profile
from cdpr_twin.sim.onboard_camera import OnboardCamera
from cdpr_twin.vision import detection as vision


@pytest.fixture(scope="module")
def frames():
    """Acrobot-profile frames (noise, distortion; one instant each) along p0 → p1, then p0."""
    from cdpr_twin.sim import Twin

    cam_realism = profile("acrobot").camera
    with Twin(camera=False, tension_noise_std=0.0) as twin:
        camera = OnboardCamera(
            twin.physics,
            twin.nominal.intrinsics,
            twin.nominal.tag_size,
            type(cam_realism)(**{**vars(cam_realism), "exposure_s": 0.0, "latency_ticks": 0}),
            np.random.default_rng(3),
            np.random.default_rng(4),
        )
        v0, v1 = (se3.vector_from_pose(paper_pose(p)) for p in ("p0", "p1"))
        path = [v0 + s * (v1 - v0) for s in np.linspace(0.0, 1.0, 16)] + [v0]
        out = []
        try:
            for v in path:
                twin.physics.place(se3.pose_from_vector(v))
                out.append(camera.render())
            return out, camera.calibrated, camera.calibrated_distortion, twin.nominal.tag_size
        finally:
            camera.close()


def test_the_window_finds_what_the_whole_frame_finds(frames):
    images, K, dist, size = frames
    windowed = vision.TagDetector(K, size, distortion=dist, quad_sigma=0.8, roi=True)
    whole = vision.TagDetector(K, size, distortion=dist, quad_sigma=0.8, roi=False)
    searches: list[tuple] = []  # the boxes each detect() searched
    find = windowed._find

    def spy(gray, box):
        searches.append(box)
        return find(gray, box)

    windowed._find = spy
    found_in_window = 0
    for image in images:
        searches.clear()
        a, b = windowed.detect(image), whole.detect(image)
        h, w = image.shape[:2]
        found_in_window += len(searches) == 1 and searches[0] != (0, 0, w, h)
        assert (a is None) == (b is None)
        if a is None:
            continue
        # measured: ≤ 3e-4 px, 6e-8 m, 3e-4° (a face-on tag's tilt moves ~1°/px); the corners'
        # noise in these frames is 0.01–0.2 px, and its tilt jitter 0.05–2°
        assert np.abs(a.corners - b.corners).max() < 1e-3
        dt, dr = se3.pose_distance(a.T_cam_tag, b.T_cam_tag)
        assert dt < 1e-6 and np.degrees(dr) < 1e-3
    assert found_in_window >= len(images) - 3  # found in the window, no whole-frame search


def test_a_tag_outside_the_window_is_found_in_the_whole_frame(frames):
    images, K, dist, size = frames
    det = vision.TagDetector(K, size, distortion=dist, quad_sigma=0.8, roi=True)
    far, near = images[0], images[-2]  # p0 (small, off-centre) and p1 (large, centred)
    assert det.detect(far) is not None
    _, _, x1, y1 = det._box
    truth = vision.TagDetector(K, size, distortion=dist, quad_sigma=0.8).detect(near)
    u, v = truth.corners.T
    assert u.max() > x1 or v.max() > y1  # p1's tag does not fit in p0's window
    found = det.detect(near)
    assert found is not None and np.abs(found.corners - truth.corners).max() < 1e-3
    assert det._box[2] > x1  # the window followed the tag


def test_the_refinement_on_a_window_is_bit_identical_to_the_whole_frame(frames, monkeypatch):
    """refine_quad samples a float32 copy of a window around the corners only; its profiles
    (bilinear, border replication at the image's own edges) must be those of the whole frame."""
    from cdpr_twin.vision import corners as quad

    images, K, dist, size = frames
    det = vision.TagDetector(K, size, distortion=dist, quad_sigma=0.8)
    cases = []
    for image in images:
        gray = image[..., 0]
        c = det.detect(image).corners
        cases += [(gray, c), (gray, np.add(c, [-c[:, 0].min() + 0.3, 0.0]))]  # one at the edge
    windowed = [quad.refine_quad(g, c) for g, c in cases]
    monkeypatch.setattr(quad, "_window", lambda gray, c, hw: (gray.astype(np.float32), (0, 0)))
    whole = [quad.refine_quad(g, c) for g, c in cases]
    for a, b in zip(windowed, whole, strict=True):
        np.testing.assert_array_equal(a, b)
