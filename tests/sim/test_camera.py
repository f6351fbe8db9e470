"""Rendered frames and AprilTag detection against MuJoCo's ground-truth camera and tag frames."""

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.math import se3
from cdpr_twin.sim import camera
from cdpr_twin.vision import detection as vision


# The requirement is 2 mm / 0.5° at p1 and 1 cm / 2° at p0; the twin's rendering and the
# refined detection do far better (p1: ≈ 5 µm, p0: 0.38 mm / 0.21°, p2: 0.14 mm), and these
# tighter bounds are what pins the pixel and frame conventions (a half-pixel slip breaks them).
@pytest.mark.parametrize(
    ("name", "max_t", "max_r_deg"), [("p1", 1e-4, 0.05), ("p0", 1e-3, 0.5), ("p2", 1e-3, 0.2)]
)
def test_detected_tag_pose_matches_ground_truth(camera_twin, name, max_t, max_r_deg):
    camera_twin.reset(paper_pose(name))
    m = camera_twin.sense()
    assert m.image is not None and m.image.shape == (480, 640, 3) and m.image.dtype == np.uint8
    assert m.tag is not None, f"tag not detected at {name}"
    dt, dr = se3.pose_distance(m.tag.T_cam_tag, camera_twin.T_cam_tag)
    assert dt < max_t
    assert np.rad2deg(dr) < max_r_deg


@pytest.mark.parametrize("name", ["p0", "p1"])
def test_intrinsics_reproject_true_corners_onto_detected(camera_twin, name):
    camera_twin.reset(paper_pose(name))
    m = camera_twin.sense()
    true_corners = vision.project_points(
        camera_twin.nominal.intrinsics, camera_twin.T_cam_tag, vision.tag_corners_object(0.04)
    )
    # required: 1 px; measured 0.007 px at p1, 0.07 px at p0
    assert np.max(np.linalg.norm(m.tag.corners - true_corners, axis=1)) < 0.2


def test_camera_frame_conventions(camera_twin):
    """The OpenCV camera frame sits under the platform, looks down, image x along −x of F_p."""
    camera_twin.reset(paper_pose("p1"))
    T_pc = camera_twin.true_geometry.T_platform_cam
    np.testing.assert_allclose(T_pc[:3, 2], [0, 0, -1], atol=1e-12)  # optical axis: −z_p
    np.testing.assert_allclose(T_pc[:3, 0], [-1, 0, 0], atol=1e-12)  # image x: −x_p
    # a point straight below the camera projects to the principal point
    K = camera_twin.nominal.intrinsics
    T_bc = camera_twin.physics.T_base_cam
    below = T_bc[:3, 3] - [0, 0, 0.1]
    p_cam = se3.inverse(T_bc) @ np.append(below, 1)
    uv = vision.project_points(K, np.eye(4), p_cam[None, :3])[0]
    np.testing.assert_allclose(uv, [K.cx, K.cy], atol=1e-9)
    assert K.cx == 319.5 and K.cy == 239.5
    np.testing.assert_allclose(K.fy, 240 / np.tan(np.deg2rad(30)))


def test_goal_pose_at_p1_and_paper_view_at_p0(camera_twin):
    """The tag is placed so that cp_o1 (ViSP frame) holds at p1; at p0 the camera
    sees it within a few cm of the paper's cp_o0."""
    visp = vision.T_TAGPUPIL_TAGVISP
    camera_twin.reset(paper_pose("p1"))
    goal = se3.pose_from_vector([0, 0, 0.09, 180, 0, 180])
    dt, dr = se3.pose_distance(camera_twin.T_cam_tag @ visp, goal)
    assert dt < 1e-9 and dr < 1e-9
    camera_twin.reset(paper_pose("p0"))
    paper = se3.pose_from_vector([-0.123, -0.101, 0.338, 168, -8, -179])
    dt, dr = se3.pose_distance(camera_twin.T_cam_tag @ visp, paper)
    assert dt < 0.05 and np.rad2deg(dr) < 5.0
    m = camera_twin.sense()
    dt, dr = se3.pose_distance(m.tag.T_cam_tag @ visp, paper)
    assert dt < 0.05 and np.rad2deg(dr) < 5.0


def test_tag_out_of_view_is_reported_as_none(camera_twin):
    camera_twin.reset(se3.pose_from_vector([-0.2, 0.2, 0.3, 0, 0, 0]))
    m = camera_twin.sense()
    assert m.image is not None and m.tag is None


def test_frames_the_buffer_or_the_memory_cannot_hold_are_refused(monkeypatch):
    camera.check_frame_size(640, 480, 4)
    with pytest.raises(ValueError, match=r"17000×480 px: more than an offscreen buffer .* resolu"):
        camera.check_frame_size(17000, 480)
    with pytest.raises(ValueError, match=r"16000×12000 px.*supersample"):
        camera.check_frame_size(640, 480, 25)
    monkeypatch.setattr(camera, "_available_memory", lambda: 2_000_000_000)
    camera.check_frame_size(640, 480, 6)  # 1.8 GB of images
    with pytest.raises(ValueError, match=r"about 3\.1 GB of images .* than the 2\.0 GB"):
        camera.check_frame_size(640, 480, 8)
