"""Which way the tag's texture lies on the floor, as models/acrobot/make_tag_texture.py says.

Truth: the camera's own frame. At p1 (platform level) the platform camera's OpenCV y axis
(image-down) is the base's +y, so a band drawn along the texture file's top edge must render in
the upper half of the frame exactly when that edge lies towards the base's −y.
"""

import cv2
import numpy as np

from cdpr_twin import resources
from cdpr_twin.math import se3
from cdpr_twin.sim import Twin


def test_the_texture_files_top_edge_lies_towards_base_minus_y(tmp_path):
    copy = resources.copy_robot("acrobot", tmp_path / "acrobot")
    png = copy.parent / "assets" / "tag36h11_00000.png"
    img = cv2.imread(str(png))
    img[2:12, 10:-10] = (0, 0, 255)  # BGR red, in the white margin along the top edge
    cv2.imwrite(str(png), img)
    with Twin(copy.parent / "scene.xml") as twin:
        twin.reset(se3.pose_from_vector([0.284, -0.197, 0.08, 0, 0, 0]))
        R_base_cam = (twin.physics.T_base_platform @ twin.nominal.geometry.T_platform_cam)[:3, :3]
        image = twin.sense().image
    assert np.allclose(R_base_cam[:, 1], [0, 1, 0], atol=1e-9)  # image-down is the base's +y
    red = (image[..., 0] > 150) & (image[..., 1] < 80) & (image[..., 2] < 80)
    rows, _ = np.nonzero(red)
    assert red.sum() > 1000  # the band is seen (measured: 7 128 px)
    # the tag's centre is near the image centre at p1 (the goal view); the band far above it
    assert rows.max() < image.shape[0] / 2
