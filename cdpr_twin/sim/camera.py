"""Onboard camera: offscreen rendering, intrinsics, and the MuJoCo ↔ OpenCV frame change.

MuJoCo cameras look along their −z with y up; OpenCV cameras look along +z with y down. The two
differ by a rotation of π about x, applied here and nowhere else.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np

from cdpr_twin.math.se3 import matrix_from_quat_wxyz, rot_x, transform
from cdpr_twin.options import OptionError
from cdpr_twin.sim import gl_contexts
from cdpr_twin.sim.imaging import lens_margins
from cdpr_twin.types import CameraIntrinsics

R_MJCAM_CV = rot_x(np.pi)
"""Rotation from the OpenCV camera frame to MuJoCo's camera frame (its own inverse)."""

CAMERA_NAME = "platform_cam"
MAX_BUFFER_PX = 16384
"""The largest offscreen buffer side of Mesa's renderers (llvmpipe's) [px]."""
BYTES_PER_SAMPLE = 160
"""A run's peak memory per rendered sample (supersampled pixel) [B]: measured 112-145 B with
``supersample`` 4, 8 and 10 on ``paper_pbvs`` (GL buffers, the renders of the exposure and of
the latency pipeline, the float32 images formed from them), above a 0.5 GB run."""


def check_frame_size(
    width: int, height: int, scale: int = 1, margins: tuple[int, int] = (0, 0)
) -> None:
    """Refuse a render the offscreen buffer cannot hold, or that would exhaust the memory.

    Args:
        width: the camera's resolution across [px].
        height: the camera's resolution down [px].
        scale: samples per pixel side (``realism.camera.supersample``).
        margins: render pixels beyond the camera's field on each side, (x, y), for a lens
            (:func:`~cdpr_twin.sim.imaging.lens_margins`).

    Raises:
        ValueError: saying which limit and what to lower (an ``OptionError`` naming
            ``realism.camera.supersample`` when that multiplies the render).
    """
    field = "realism.camera.supersample" if scale > 1 else "the camera's resolution"

    def error(text: str) -> ValueError:
        return OptionError(field, text) if scale > 1 else ValueError(text)

    w, h = width * scale + 2 * margins[0], height * scale + 2 * margins[1]
    size = f"{w}×{h} px"
    if margins[0] or margins[1]:
        size += f" (a {width * scale}×{height * scale} px frame and what the lens sees beyond it)"
    if max(w, h) > MAX_BUFFER_PX:
        raise error(
            f"the camera renders {size}: more than an offscreen "
            f"buffer can hold ({MAX_BUFFER_PX} px a side with Mesa); lower {field}"
        )
    need = BYTES_PER_SAMPLE * w * h
    free = _available_memory()
    if free is not None and need > free:
        raise error(
            f"the camera renders {size}, which takes about "
            f"{need / 1e9:.1f} GB of images ({BYTES_PER_SAMPLE} B a sample), more than the "
            f"{free / 1e9:.1f} GB of memory available; lower {field}"
        )


def _available_memory() -> int | None:
    """Memory the kernel can give without swapping [B] (Linux's MemAvailable), or ``None``."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def has_camera(model: mujoco.MjModel, name: str = CAMERA_NAME) -> bool:
    """Whether the model has a camera of that name."""
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name) >= 0


def camera_id(model: mujoco.MjModel, name: str = CAMERA_NAME) -> int:
    """Id of a named camera, with an error that says what the model lacks."""
    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    if cid < 0:
        raise ValueError(
            f"the model has no camera named {name!r}; add <camera name={name!r}> "
            "to the platform body"
        )
    return cid


def intrinsics(model: mujoco.MjModel, name: str = CAMERA_NAME) -> CameraIntrinsics:
    """OpenCV intrinsics of a MuJoCo camera rendered at its ``resolution`` attribute."""
    cid = camera_id(model, name)
    width, height = (int(v) for v in model.cam_resolution[cid])
    return CameraIntrinsics.from_fovy(width, height, np.deg2rad(model.cam_fovy[cid]))


def T_body_cam(model: mujoco.MjModel, name: str = CAMERA_NAME) -> np.ndarray:
    """(4, 4) OpenCV camera frame in the frame of the body carrying the camera."""
    cid = camera_id(model, name)
    R = matrix_from_quat_wxyz(model.cam_quat[cid]) @ R_MJCAM_CV
    return transform(R, model.cam_pos[cid])


def T_world_cam(data: mujoco.MjData, cid: int) -> np.ndarray:
    """(4, 4) OpenCV camera frame in the world (base) frame, from current kinematics."""
    return transform(data.cam_xmat[cid].reshape(3, 3) @ R_MJCAM_CV, data.cam_xpos[cid])


def scene_key(scene: mujoco.MjvScene) -> bytes | None:
    """What the renderer draws of ``scene``, as bytes: equal keys draw the same image.

    Every geom's kind, object, material, size, colour and pose, every light's, and the
    camera's pose and frustum, in the single precision ``mjvScene`` holds them in (the
    flags, options and textures are the renderer's own, fixed). ``None`` for a scene with
    flexes or skins, whose vertices the key leaves out.
    """
    if scene.nflex or scene.nskin:
        return None
    parts = []
    for g in scene.geoms[: scene.ngeom]:
        ids = (g.type, g.dataid, g.objtype, g.objid, g.matid, g.texcoord, g.segid)
        parts += [np.array(ids, np.float32), g.size, g.pos, g.mat, g.rgba]
    for light in scene.lights[: scene.nlight]:
        parts += [light.pos, light.dir, light.diffuse, light.ambient, light.specular]
    for cam in scene.camera:
        frustum: tuple[float, ...] = (cam.frustum_center, cam.frustum_width, cam.frustum_bottom)
        frustum += (cam.frustum_top, cam.frustum_near, cam.frustum_far, cam.orthographic)
        parts += [cam.pos, cam.forward, cam.up, np.array(frustum, np.float32)]
    # a list, not a generator: one call, where a generator resumes once per part (≈ 900)
    return b"".join([np.asarray(p, np.float32).tobytes() for p in parts])


class CameraRenderer:
    """Offscreen RGB rendering of one camera, at its native resolution or supersampled.

    Args:
        model: the compiled model (its ``<visual><global offwidth offheight>`` must be at least
            the camera resolution; for ``scale`` > 1 or ``margins`` it is enlarged here to the
            rendered size, which changes nothing but the offscreen buffer).
        name: camera name.
        scale: render ``scale`` × ``scale`` samples per camera pixel (the same field of view;
            :attr:`render_intrinsics` are the supersampled image's).
        lens: the true lens's (k1, k2, p1, p2), or ``None`` (a pinhole). A barrel lens images
            scene points beyond the pinhole's field onto the sensor's edges: the render then
            reaches :attr:`margins` (x, y) pixels (supersampled ones) beyond the camera's field
            on each side, a wider :attr:`canvas` with the same focal length and pixel grid
            (:func:`~cdpr_twin.sim.imaging.lens_margins`).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        name: str = CAMERA_NAME,
        scale: int = 1,
        lens: tuple[float, ...] | None = None,
    ) -> None:
        self.camera_id = camera_id(model, name)
        self._model = model
        self._scratch: mujoco.MjData | None = None
        self._last: tuple[bytes | None, np.ndarray | None] = (None, None)  # the last drawn
        self.intrinsics = intrinsics(model, name)
        self.render_intrinsics = self.intrinsics.scaled(scale)
        check_frame_size(self.intrinsics.width, self.intrinsics.height, scale)  # before margins
        self.margins = lens_margins(self.render_intrinsics, lens) if lens else (0, 0)
        self.canvas = K = self.render_intrinsics.widened(*self.margins)
        w, h = self.intrinsics.width, self.intrinsics.height
        check_frame_size(w, h, scale, self.margins)
        # the canvas's vertical field of view (MuJoCo's cameras are symmetric frusta: the
        # same margins on both sides keep the principal point, and the focal length, as is)
        self._fovy = None
        if any(self.margins):
            self._fovy = float(np.rad2deg(2.0 * np.arctan(0.5 * K.height / K.fy)))
        if scale > 1 or self._fovy is not None:
            g = model.vis.global_
            w, h = self.canvas.width, self.canvas.height
            g.offwidth, g.offheight = max(g.offwidth, w), max(g.offheight, h)
        if model.vis.global_.offwidth < w or model.vis.global_.offheight < h:
            raise ValueError(
                f"camera {name!r} renders {w}×{h} px but the offscreen buffer is "
                f"{model.vis.global_.offwidth}×{model.vis.global_.offheight}; raise "
                "<visual><global offwidth=… offheight=…/> in the model file"
            )
        try:
            self._renderer = mujoco.Renderer(model, height=h, width=w)
            self._free = gl_contexts.owned(self, self._renderer)
        except Exception as exc:
            raise RuntimeError(
                f"offscreen rendering failed ({exc}). MuJoCo chose its GL backend from "
                f"MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} when it was first imported: import "
                "cdpr_twin before mujoco (or export MUJOCO_GL=egl), make sure Mesa's EGL "
                "(libegl1) is installed, or run with the camera off"
            ) from exc
        self._option = mujoco.MjvOption()
        self._option.sitegroup[:] = 0  # sites are markers for people, not for the camera
        self._option.tendongroup[:] = 1

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """Render the camera's view: (H, W, 3) RGB uint8 of the canvas, top row first.

        A scene that draws exactly as the last one (every geom, light and the camera equal in
        the single precision the renderer draws with: a robot at rest between the sub-frames
        of an exposure) gives a copy of the last image instead of drawing it again.
        """
        if self._fovy is None:
            self._renderer.update_scene(data, camera=self.camera_id, scene_option=self._option)
        else:
            fovy = self._model.cam_fovy[self.camera_id]
            self._model.cam_fovy[self.camera_id] = self._fovy  # the scene's frustum takes it
            try:
                self._renderer.update_scene(data, camera=self.camera_id, scene_option=self._option)
            finally:
                self._model.cam_fovy[self.camera_id] = fovy
        key = scene_key(self._renderer.scene)
        last_key, image = self._last
        # (no image yet: no key either, so the first call always draws)
        if image is None or key is None or key != last_key:
            image = self._renderer.render()
            self._last = (key, image)
        return image.copy()

    def render_state(
        self, qpos: np.ndarray, mocap_pos: np.ndarray, mocap_quat: np.ndarray
    ) -> np.ndarray:
        """Render the view at a recorded state (the simulation's own data is not touched).

        The state is loaded into a scratch ``MjData`` whose positions (bodies, camera, lights,
        tendon paths) are computed from it, so the frame shows exactly that state.

        Args:
            qpos: (nq,) joint positions.
            mocap_pos: (nmocap, 3) mocap body positions (the pulley swivels).
            mocap_quat: (nmocap, 4) mocap body orientations.

        Returns:
            (H, W, 3) RGB uint8, top row first.
        """
        if self._scratch is None:
            self._scratch = mujoco.MjData(self._model)
        d = self._scratch
        d.qpos[:], d.mocap_pos[:], d.mocap_quat[:] = qpos, mocap_pos, mocap_quat
        mujoco.mj_fwdPosition(self._model, d)
        return self.render(d)

    def close(self) -> None:
        """Free the GL context (dropped unclosed, :mod:`~cdpr_twin.sim.gl_contexts` frees it)."""
        if self._renderer is not None:
            self._free()
            self._renderer = None
