"""Generate the AprilTag texture of the scene: tag36h11 id 0 on a white plate.

Run from anywhere: ``python models/acrobot/make_tag_texture.py``. It writes
``assets/tag36h11_00000.png`` beside this file. OpenCV's ``DICT_APRILTAG_36h11`` dictionary
holds the same codes that pupil-apriltags detects.

The image is PLATE_CELLS × PLATE_CELLS cells: the tag's 8 × 8 black-bordered code (the 4 cm
"tag size" that pose estimation uses) centred on white, so that the plate geom (7 cm wide in
scene.xml) shows the code 4 cm wide. Seen from above, the file's top edge lies towards −y of
the base frame: a band drawn along it renders in the top of the platform camera's frame at p1,
whose image-up is the base's −y (the camera's OpenCV y, image-down, is the base's +y there).
The tag body's frame, the pupil-apriltags tag frame, agrees with detection
(tests/sim/test_camera.py).
"""

from pathlib import Path

import cv2
import numpy as np

TAG_ID = 0
CODE_CELLS = 8  # black border + 6 × 6 data bits
PLATE_CELLS = 14  # 3 white cells each side: 14 × 5 mm = 7 cm plate
CELL_PX = 8  # texels per cell: the texture stays magnified (see below)


def main() -> None:
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    code = cv2.aruco.generateImageMarker(dictionary, TAG_ID, CODE_CELLS * CELL_PX)
    pad = (PLATE_CELLS - CODE_CELLS) // 2 * CELL_PX
    img = np.pad(code, pad, constant_values=255)
    out = Path(__file__).resolve().parent / "assets" / f"tag36h11_{TAG_ID:05d}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), img):
        raise OSError(f"could not write {out}")
    print(f"wrote {out} ({img.shape[1]}×{img.shape[0]} px)")


if __name__ == "__main__":
    main()
