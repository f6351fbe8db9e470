"""A sheet that can hide the tag from the camera: occlusion by geometry, not by skipping detection.

A ``tag_occlusion`` event needs something in the scene to hide the tag, as a hand or a cable
passing over it would on the real robot. :func:`add_occluder` adds to the model (through
MjSpec, only for scenarios that schedule an occlusion, so every other model is unchanged) a
mocap body ``tag_occluder`` holding a thin matte sheet that collides with nothing. An
:class:`Occluder` moves it:

- covering: the sheet floats ``GAP`` above the tag plate (between the tag and the camera),
  covering the fraction ``coverage`` of the tag's code width from its −x edge (1 hides the
  code whole; a partial cover hides part of the border and code, as a real obstruction does);
- parked: the sheet lies ``PARK_DEPTH`` under the tag plate, below the opaque floor, where no
  camera above the floor sees it (a test checks the frames are pixel-identical to a scene
  without the sheet).

The rendered frame then simply shows the sheet; whether the tag is still found is up to the
detector.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

OCCLUDER_BODY = "tag_occluder"
GAP = 0.01
"""Height of the sheet above the tag plate when it covers the tag [m]."""
PARK_DEPTH = 0.2
"""Depth of the parked sheet below the tag plate (under the floor) [m]."""
_MARGIN = 0.006
"""How far the sheet reaches past the tag's plate in y and past the code edge in x [m]."""
_RGBA = (0.55, 0.45, 0.35, 1.0)  # matte cardboard


def add_occluder(spec: mujoco.MjSpec, half_plate: float) -> None:
    """Add the parked occluding sheet to a model spec.

    Args:
        spec: the scene's spec (with a tag).
        half_plate: half the side of the tag's square plate [m].
    """
    body = spec.worldbody.add_body(name=OCCLUDER_BODY, mocap=True, pos=[0.0, 0.0, -10.0])
    half = half_plate + _MARGIN
    body.add_geom(
        name="tag_occluder_sheet",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half, half, 0.0005],
        rgba=list(_RGBA),
        contype=0,
        conaffinity=0,
        group=1,
    )


def occluder_of(model: mujoco.MjModel, data: mujoco.MjData, T_base_tag) -> Occluder | None:
    """The model's occluder (placed parked), or ``None`` when it has none.

    Args:
        model: the compiled model.
        data: its data.
        T_base_tag: a callable giving the (4, 4) tag pose (called only when there is a sheet).
    """
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OCCLUDER_BODY) < 0:
        return None
    size_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "tag_size")
    plate = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "tag_plate")
    if size_id < 0 or plate < 0:
        raise ValueError("an occluder needs the scene's <numeric name='tag_size'> and tag_plate")
    tag_size = float(model.numeric_data[model.numeric_adr[size_id]])
    return Occluder(model, data, T_base_tag(), tag_size, float(model.geom_size[plate, 0]))


class Occluder:
    """Moves the occluding sheet over the tag or parks it.

    Args:
        model: a model built with :func:`add_occluder`.
        data: its data.
        T_base_tag: (4, 4) the tag's pose (pupil-apriltags frame: z into the plate).
        tag_size: the side of the tag's code [m].
        half_plate: half the side of the tag's plate [m].

    Raises:
        ValueError: when the model has no occluder.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        T_base_tag: np.ndarray,
        tag_size: float,
        half_plate: float,
    ) -> None:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OCCLUDER_BODY)
        if body < 0 or model.body_mocapid[body] < 0:
            raise ValueError(f"the model has no mocap body {OCCLUDER_BODY!r}")
        self._mocap = int(model.body_mocapid[body])
        self._data, self._T = data, np.asarray(T_base_tag, dtype=float)
        self._tag_size, self._half = float(tag_size), half_plate + _MARGIN
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, self._T[:3, :3].ravel())
        data.mocap_quat[self._mocap] = quat
        self.coverage = 0.0
        self.cover(0.0)

    def cover(self, coverage: float) -> None:
        """Hide the fraction ``coverage`` (0…1) of the tag's code width; 0 parks the sheet.

        Raises:
            ValueError: for a coverage outside [0, 1].
        """
        if not (math.isfinite(coverage) and 0.0 <= coverage <= 1.0):
            raise ValueError(f"coverage must be in [0, 1], got {coverage}")
        if coverage == 0.0:
            local = np.array([0.0, 0.0, PARK_DEPTH])  # z into the plate: below the floor
        else:
            edge = -0.5 * self._tag_size + coverage * self._tag_size  # the sheet's +x edge
            local = np.array([edge - self._half, 0.0, -GAP])  # −z: towards the camera
        self._data.mocap_pos[self._mocap] = self._T[:3, :3] @ local + self._T[:3, 3]
        self.coverage = float(coverage)
