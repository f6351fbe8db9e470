"""Est. 2, image-based: compose two tag poses (paper §III-B, eq. 10-12)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from cdpr_twin.estimators.base import (
    NO_CAMERA,
    NON_FINITE_INPUT,
    REANCHORED,
    TAG_LOST,
    Estimator,
)
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import inverse
from cdpr_twin.options import OptionError, option
from cdpr_twin.types import Measurement, PoseEstimate


@dataclass(frozen=True)
class ImageOptions:
    """Options of the image-based estimator.

    Attributes:
        reference: ``"previous"`` — compose successive detections (the paper's choice);
            ``"first"`` — compose against the first detection after reset.
    """

    reference: Literal["previous", "first"] = option("previous")

    def __post_init__(self) -> None:
        if self.reference not in ("previous", "first"):
            raise OptionError("reference", f"must be 'previous' or 'first', got {self.reference!r}")


class ImageEstimator(Estimator):
    """ᵇT_p(t) = ᵇT_p(t0) ᵖT_c ᶜT_o(t0) ᶜT_o(t)⁻¹ ᵖT_c⁻¹ (eq. 12), the tag being motionless.

    Args:
        geometry: nominal geometry (its ``T_platform_cam`` is ᵖT_c).
        options: :class:`ImageOptions`; ``reference="previous"``: t0 = t − Δt, successive
            detections (the paper's choice); ``"first"``: t0 is the first detection after
            :meth:`reset`.

    The first detection after :meth:`reset` anchors the tag in F_b at the reset pose (eq. 10):
    feed the measurement taken at that pose first.

    Tag lost (or no image): the estimate is held and flagged. With ``"first"`` the next
    detection resumes against the first one, so nothing is lost. With ``"previous"`` the next
    detection has no predecessor at t − Δt: the estimator re-anchors there at the held estimate
    (flag ``reanchored``), so the motion made while the tag was lost is lost — the drift of
    successive composition. While every tick has a detection the two references give the same
    pose: the successive products telescope (X₀X₁⁻¹·X₁X₂⁻¹ = X₀X₂⁻¹).
    """

    name = "image"
    Options = ImageOptions
    needs_camera = True

    def __init__(self, geometry: CdprGeometry, options: ImageOptions | None = None) -> None:
        super().__init__(geometry, options)
        self.reference = self.options.reference
        self._T_base_tag: np.ndarray | None = None
        self._had_tag = False

    def reset(self, T_base_platform0: np.ndarray, time: float = 0.0) -> None:
        """Start from a known pose; the next detection becomes the reference."""
        super().reset(T_base_platform0, time)
        self._T_base_tag = None
        self._had_tag = False

    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """Compose the estimate from the reference detection and this one."""
        m = measurement
        if m.tag is None:
            self._had_tag = False
            return self._held(m, TAG_LOST if m.camera_on else NO_CAMERA)
        T_platform_tag = self.geometry.T_platform_cam @ m.tag.T_cam_tag  # ᵖT_c ᶜT_o(t)
        if not np.all(np.isfinite(T_platform_tag)):
            self._had_tag = False
            return self._held(m, NON_FINITE_INPUT)
        flags: frozenset[str] = frozenset()
        restart = self.reference == "previous" and not self._had_tag
        if self._T_base_tag is None or restart:
            # ᵇT_o from the estimate at t0 (eq. 10); re-anchoring after a gap loses the motion
            if self._T_base_tag is not None:
                flags = frozenset({REANCHORED})
            self._T_base_tag = self._T @ T_platform_tag
        else:
            self._T = self._T_base_tag @ inverse(T_platform_tag)
            if self.reference == "previous":
                self._T_base_tag = self._T @ T_platform_tag  # t0 ← t for the next tick
        self._had_tag = True
        self._time = m.time
        return PoseEstimate(m.time, self._T, flags=flags)
