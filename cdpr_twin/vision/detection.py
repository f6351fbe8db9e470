"""AprilTag detection → ``T_cam_tag`` (pupil-apriltags for detection, OpenCV for the pose).

Frames: ``cam`` is the OpenCV camera frame (x right, y down, z forward); ``tag`` is the
pupil-apriltags object frame (origin at the tag centre, x right and y down on the printed tag,
z into it). Pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).
AprilTag reports corners with that centre at (0.5, 0.5) (AprilRobotics/apriltag#121), so the
detector shifts them by −0.5 px before solving the pose with the intrinsics K it is given (the
robot's calibration; in the ideal twin, those :mod:`cdpr_twin.sim.camera` derives from the
rendering camera). A lens with Brown–Conrady distortion (k1, k2, p1, p2) curves the tag's
edges: the detector then straightens the edge points with its calibrated coefficients before it
fits lines to them, and solves the pose on the undistorted corners.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
from pupil_apriltags import Detector

from cdpr_twin.math.se3 import transform
from cdpr_twin.types import T_TAGPUPIL_TAGVISP, CameraIntrinsics, TagDetection
from cdpr_twin.vision.corners import refine_quad

__all__ = [
    "T_TAGPUPIL_TAGVISP",
    "CameraIntrinsics",
    "TagDetection",
    "TagDetector",
    "distort_pixels",
    "project_points",
    "refine_quad",
    "tag_corners_object",
    "undistort_pixels",
]

APRILTAG_PIXEL_OFFSET = 0.5
"""AprilTag's pixel-centre coordinate minus OpenCV's [px]."""


class _Detector(Detector):
    """pupil-apriltags' Detector with its destructor's use-after-free fixed.

    Upstream ``Detector.__del__`` destroys the tag families before the C detector, whose
    destruction still reads them (``apriltag_detector_clear_families`` → ``quick_decode_uninit``):
    an intermittent segfault at garbage collection (pupil-labs/apriltags#46; fixed the same way
    in duckietown/lib-dt-apriltags#26). Here the detector goes first, as in AprilTag's examples.
    """

    def __del__(self) -> None:
        ptr = getattr(self, "tag_detector_ptr", None)
        if ptr is None:
            return
        self.tag_detector_ptr = None
        self.libc.apriltag_detector_destroy.restype = None
        self.libc.apriltag_detector_destroy(ptr)
        families = self.tag_families
        self.tag_families: dict[str, Any] = {}
        for family, tf in families.items():
            destroy = getattr(self.libc, f"{family}_destroy")
            destroy.restype = None
            destroy(tf)


def tag_corners_object(tag_size: float) -> np.ndarray:
    """Tag corners in the tag frame, in the order of :attr:`TagDetection.corners`. (4, 3) [m]."""
    h = 0.5 * tag_size
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def project_points(
    intrinsics: CameraIntrinsics, T_cam_obj: np.ndarray, points_obj: np.ndarray
) -> np.ndarray:
    """Pinhole projection of points given in an object frame.

    Args:
        intrinsics: camera intrinsics.
        T_cam_obj: (4, 4) object pose in the camera frame.
        points_obj: (n, 3) points [m].

    Returns:
        (n, 2) pixel coordinates (OpenCV convention).
    """
    p = points_obj @ T_cam_obj[:3, :3].T + T_cam_obj[:3, 3]
    uv = p[:, :2] / p[:, 2:3]
    return uv * [intrinsics.fx, intrinsics.fy] + [intrinsics.cx, intrinsics.cy]


def tag_pixels(intrinsics: CameraIntrinsics, T_cam_tag: np.ndarray, tag_size: float):
    """The tag's corners in the image, and whether the whole tag is in front of the camera.

    Args:
        intrinsics: camera intrinsics.
        T_cam_tag: (4, 4) tag pose in the camera frame.
        tag_size: edge of the tag's black square [m].

    Returns:
        ``(uv, in_front)``: (4, 2) pinhole pixels of the corners (meaningless for corners
        behind the camera) and whether every corner is in front of it.
    """
    corners = tag_corners_object(tag_size)
    in_front = bool(np.all(corners @ T_cam_tag[2, :3] + T_cam_tag[2, 3] > 0))
    return project_points(intrinsics, T_cam_tag, corners), in_front


def inside_image(intrinsics: CameraIntrinsics, uv: np.ndarray, margin: float = 0.0) -> bool:
    """Whether every pixel of ``uv`` (n, 2) lies ``margin`` px or more inside the image."""
    hi = np.array([intrinsics.width, intrinsics.height]) - margin
    return bool(np.all(uv >= margin) and np.all(uv <= hi))


UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
"""OpenCV's iterative undistortion to convergence (its default stops after 5 iterations)."""


def undistort_pixels(
    intrinsics: CameraIntrinsics, distortion: Sequence[float], pixels: np.ndarray
) -> np.ndarray:
    """Pixels of a distorting lens → the pixels an ideal pinhole of the same K would see.

    Args:
        intrinsics: camera intrinsics K.
        distortion: Brown–Conrady (k1, k2, p1, p2).
        pixels: (n, 2) observed (distorted) pixels.

    Returns:
        (n, 2) undistorted pixels.
    """
    K = intrinsics.K
    src = np.asarray(pixels, dtype=float).reshape(-1, 1, 2)
    dist = np.asarray(distortion, dtype=float)
    out = cv2.undistortPoints(src, K, dist, R=np.eye(3), P=K, criteria=UNDISTORT_CRITERIA)
    return out.reshape(-1, 2)


def distort_pixels(
    intrinsics: CameraIntrinsics, distortion: Sequence[float], pixels: np.ndarray
) -> np.ndarray:
    """Ideal pinhole pixels → where the distorting lens images them (inverse of the above).

    Args:
        intrinsics: camera intrinsics K.
        distortion: Brown–Conrady (k1, k2, p1, p2).
        pixels: (n, 2) undistorted pixels.

    Returns:
        (n, 2) distorted pixels.
    """
    K = intrinsics
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    xy1 = np.column_stack([(uv[:, 0] - K.cx) / K.fx, (uv[:, 1] - K.cy) / K.fy, np.ones(len(uv))])
    zero = np.zeros(3)
    dist = np.asarray(distortion, dtype=float)
    return cv2.projectPoints(xy1, zero, zero, K.K, dist)[0].reshape(-1, 2)


ROI_MARGIN = (48, 0.5)
"""The search window around the last tag: (at least [px], at least × the tag's extent)."""


def _box_around(corners: np.ndarray, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1): the corners' bounding box grown by :data:`ROI_MARGIN`, on an 8-px grid.

    The grid keeps AprilTag's decimation and threshold tiles aligned with the whole frame's.
    """
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    pad = np.maximum(ROI_MARGIN[0], ROI_MARGIN[1] * (hi - lo))
    x0, y0 = (max(0, int(v) // 8 * 8) for v in np.floor(lo - pad))
    x1, y1 = (min(n, -(-int(v) // 8) * 8) for v, n in zip(np.ceil(hi + pad), size, strict=True))
    return x0, y0, x1, y1


def _well_inside(corners: np.ndarray, box: tuple[int, int, int, int], size: tuple) -> bool:
    """Whether the corners keep 8 px from every window edge that is not the frame's edge."""
    x0, y0, x1, y1 = box
    (u0, v0), (u1, v1) = corners.min(axis=0), corners.max(axis=0)
    return (
        (x0 == 0 or u0 - x0 >= 8)
        and (y0 == 0 or v0 - y0 >= 8)
        and (x1 == size[0] or x1 - u1 >= 8)
        and (y1 == size[1] or y1 - v1 >= 8)
    )


class TagDetector:
    """Detect one AprilTag and estimate its pose in the camera frame.

    Args:
        intrinsics: camera intrinsics of the images to come.
        tag_size: edge of the tag's black square [m].
        tag_id: the id to look for; other ids are ignored.
        family: AprilTag family.
        quad_decimate: pupil-apriltags' decimation (1.0 = full resolution, most accurate).
        nthreads: detector threads.
        refine_corners: refine pupil-apriltags' corners with :func:`refine_quad` (its quad fit
            is biased by up to 0.3 px on edges aligned with the pixel grid).
        distortion: the lens's calibrated Brown–Conrady (k1, k2, p1, p2); ``None`` (or zeros)
            for a pinhole. Corners are undistorted with it (and ``intrinsics``) before the pose
            (the reprojection error is then in undistorted pixels).
        quad_sigma: Gaussian blur of AprilTag's segmentation image [px] (0: none); noisy
            images are found faster and more reliably with about 0.8.
        roi: search first around the last detection (a window :data:`ROI_MARGIN` wider than
            the tag each side), the whole frame when the tag is not found well inside it.
            Cheaper, and equal to a whole-frame search to ≤ 3e-4 px (typically 1e-5), not bit
            for bit: AprilTag's quad fit sums coordinates the window shifts
            (``tests/vision/test_tag_search.py``).
    """

    def __init__(
        self,
        intrinsics: CameraIntrinsics,
        tag_size: float = 0.04,
        tag_id: int = 0,
        family: str = "tag36h11",
        quad_decimate: float = 2.0,
        nthreads: int = 1,
        refine_corners: bool = True,
        distortion: Sequence[float] | None = None,
        quad_sigma: float = 0.0,
        roi: bool = False,
    ) -> None:
        if not tag_size > 0:
            raise ValueError(f"tag_size must be > 0 m, got {tag_size}")
        K = intrinsics
        if not (K.fx > 0 and K.fy > 0 and 0 <= K.cx <= K.width and 0 <= K.cy <= K.height):
            raise ValueError(  # the detector's pose fit would run on nonsense (or crash in C)
                f"intrinsics fx={K.fx:g}, fy={K.fy:g} px, principal point ({K.cx:g}, {K.cy:g}) "
                f"px: need positive focal lengths and the point inside the {K.width}×{K.height} "
                "px image"
            )
        self.intrinsics = intrinsics
        self.tag_size = float(tag_size)
        self.tag_id = int(tag_id)
        self._detector = _Detector(
            families=family,
            nthreads=nthreads,
            quad_decimate=quad_decimate,
            quad_sigma=quad_sigma,
            refine_edges=True,
        )
        self._object_points = tag_corners_object(self.tag_size)
        self.roi = bool(roi)
        self._box: tuple[int, int, int, int] | None = None
        self.refine_corners = bool(refine_corners)
        self.distortion: tuple[float, ...] | None = None
        if distortion is not None and np.any(np.asarray(distortion, dtype=float) != 0):
            if len(distortion) != 4:
                raise ValueError(f"distortion must be (k1, k2, p1, p2), got {distortion}")
            self.distortion = tuple(float(c) for c in distortion)

    def forget(self) -> None:
        """Forget where the tag was (after a reset): the next search covers the whole frame."""
        self._box = None

    def _find(self, gray: np.ndarray, box: tuple[int, int, int, int]) -> tuple | None:
        """The best detection of the tag in ``gray[y0:y1, x0:x1]`` and its corners in the frame.

        The corners come back in the whole frame's OpenCV pixels, and the pose seed is solved
        with the principal point moved into the window, so both mean what they do for a search
        of the whole frame.
        """
        x0, y0, x1, y1 = box
        K, off = self.intrinsics, APRILTAG_PIXEL_OFFSET
        params = (K.fx, K.fy, K.cx + off - x0, K.cy + off - y0)
        part = np.ascontiguousarray(gray[y0:y1, x0:x1])
        found = [
            d
            for d in self._detector.detect(part, True, params, self.tag_size)
            if d.tag_id == self.tag_id
        ]
        if not found:
            return None
        det = max(found, key=lambda d: d.decision_margin)
        return det, np.asarray(det.corners, dtype=float) - off + [x0, y0]

    def _undistort(self, pixels: np.ndarray) -> np.ndarray:
        # detect() calls it only for a lens with distortion
        assert self.distortion is not None
        return undistort_pixels(self.intrinsics, self.distortion, pixels)

    def detect(self, image: np.ndarray) -> TagDetection | None:
        """Find the tag in an image.

        Args:
            image: (H, W, 3) RGB uint8 or (H, W) grayscale uint8.

        Returns:
            The detection, or ``None`` when the tag is not found (lost, occluded, out of view).
        """
        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim not in (2, 3):
            raise ValueError(
                f"image must be (H, W) or (H, W, 3) uint8, got {img.shape} {img.dtype}"
            )
        gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
        h, w = gray.shape
        hit = None
        if self._box is not None:  # where the tag was: a small search first
            hit = self._find(gray, self._box)
            if hit is not None and not _well_inside(hit[1], self._box, (w, h)):
                hit = None  # it may be cut by the window's edge: look at the whole frame
        if hit is None:
            hit = self._find(gray, (0, 0, w, h))
        self._box = None if hit is None or not self.roi else _box_around(hit[1], (w, h))
        if hit is None:
            return None
        det, corners = hit
        undistort = None if self.distortion is None else self._undistort
        if self.refine_corners:
            corners = refine_quad(gray, corners, undistort=undistort)
        elif undistort is not None:
            corners = undistort(corners)
        best = self._best_pose(det, corners)
        if best is None:
            return None
        T = best
        err = project_points(self.intrinsics, T, self._object_points) - corners
        if self.distortion is not None:  # report them where they are in the image
            corners = distort_pixels(self.intrinsics, self.distortion, corners)
        return TagDetection(
            tag_id=int(det.tag_id),
            corners=corners,
            T_cam_tag=T,
            decision_margin=float(det.decision_margin),
            reprojection_error=float(np.sqrt(np.mean(np.sum(err**2, axis=1)))),
        )

    def _best_pose(self, det, corners: np.ndarray) -> np.ndarray | None:
        """The best-reprojecting of pupil-apriltags' pose and both IPPE solutions, refined.

        Planar targets have two nearly equally good poses when seen face-on from afar: each
        seed is refined with LM on the OpenCV-convention corners. Returns (4, 4) or ``None``.
        """
        seeds = [(cv2.Rodrigues(np.asarray(det.pose_R))[0], np.asarray(det.pose_t).reshape(3, 1))]
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            self._object_points, corners, self.intrinsics.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        seeds += list(zip(rvecs[:n], tvecs[:n], strict=True))
        best, best_err = None, np.inf
        for rvec0, tvec0 in seeds:
            # OpenCV needs (3, 1) float64 arrays here, or returns garbage
            rvec, tvec = cv2.solvePnPRefineLM(
                self._object_points,
                corners,
                self.intrinsics.K,
                None,
                np.array(rvec0, dtype=float).reshape(3, 1),
                np.array(tvec0, dtype=float).reshape(3, 1),
            )
            T_try = transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
            if T_try[2, 3] <= 0 or not np.logical_and.reduce(np.isfinite(T_try), axis=None):
                continue
            e = project_points(self.intrinsics, T_try, self._object_points) - corners
            err = float(np.add.reduce(e**2, axis=None))
            if err < best_err:
                best, best_err = T_try, err
        return best
