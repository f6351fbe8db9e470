"""The onboard camera as a sensor: render the frame, detect the tag with calibrated intrinsics.

Ideal (``CameraRealism()``): one noise-free render of the current instant through an ideal
pinhole, detected at once with the nominal intrinsics (the twin before realism, bit for bit).
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.realism import CameraRealism
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim.model import SimulationError
from cdpr_twin.sim.physics import Physics
from cdpr_twin.types import CameraIntrinsics, TagDetection


class OnboardCamera:
    """Renders what the platform camera sees and detects the tag in it.

    Args:
        physics: the simulated robot (the image is made with its *true* camera).
        intrinsics: the calibrated (nominal) intrinsics the detector uses.
        tag_size: the tag's edge the detector assumes [m].
        realism: the camera's imperfections.
        robot_rng: the per-robot generator (calibration errors).
        run_rng: the run's generator (pixel noise).
    """

    def __init__(
        self,
        physics: Physics,
        intrinsics: CameraIntrinsics,
        tag_size: float,
        realism: CameraRealism,
        robot_rng: np.random.Generator,
        run_rng: np.random.Generator,
    ) -> None:
        if not physics.has_camera:
            raise SimulationError(
                f"{physics.source} has no camera {cam_mod.CAMERA_NAME!r}; run with the camera off"
            )
        from cdpr_twin.vision import TagDetector  # OpenCV and pupil-apriltags, on demand

        self.physics, self.realism = physics, realism
        self._renderer = cam_mod.CameraRenderer(physics.model)
        try:
            self._detector = TagDetector(intrinsics, tag_size=tag_size)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Free the GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def render(self) -> np.ndarray:
        """The frame the camera takes now, (H, W, 3) RGB uint8."""
        return self._renderer.render(self.physics.data)

    def read(self) -> tuple[np.ndarray, TagDetection | None]:
        """The frame and the tag detected in it (``None`` when not found)."""
        image = self.render()
        return image, self._detector.detect(image)
