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

from collections.abc import Callable, Sequence

import cv2
import numpy as np
from pupil_apriltags import Detector

from cdpr_twin.se3 import transform
from cdpr_twin.types import T_TAGPUPIL_TAGVISP, CameraIntrinsics, TagDetection

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
        families, self.tag_families = self.tag_families, {}
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


UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
"""OpenCV's iterative undistortion to convergence (its default stops after 5 iterations)."""

PixelMap = Callable[[np.ndarray], np.ndarray]
"""A map of (n, 2) pixel coordinates to (n, 2) pixel coordinates."""


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


def _edge_line(
    img: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    edge_len: float,
    centre: np.ndarray,
    steps: np.ndarray,
    undistort: PixelMap | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Total-least-squares line (point, direction) through one edge's sub-pixel crossings.

    Profiles across the edge p0 → p1 are sampled at ``steps`` [px] along its outward normal;
    the mid-level crossing of each is an edge point (mapped by ``undistort`` when given: the
    line is then fitted where edges are straight). ``None`` with fewer than 4 points.
    """
    d = (p1 - p0) / edge_len
    n = np.array([-d[1], d[0]])
    if n @ ((p0 + p1) / 2 - centre) < 0:
        n = -n  # outward normal: dark inside, light outside
    ts = np.linspace(0.15, 0.85, max(8, int(edge_len / 2)))
    base = p0 + ts[:, None] * (p1 - p0)
    pts = base[:, None, :] + steps[None, :, None] * n  # (k, s, 2)
    prof = cv2.remap(
        img,
        pts[..., 0].astype(np.float32),
        pts[..., 1].astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    lo, hi = prof.min(axis=1, keepdims=True), prof.max(axis=1, keepdims=True)
    ok = (hi - lo).ravel() > 20.0
    f = prof - 0.5 * (lo + hi)  # rising from dark (inside) to light (outside)
    found = []
    for k in np.flatnonzero(ok):
        idx = np.flatnonzero((f[k, :-1] < 0) & (f[k, 1:] >= 0))
        if idx.size != 1:
            continue
        i = idx[0]
        t = steps[i] + (steps[i + 1] - steps[i]) * f[k, i] / (f[k, i] - f[k, i + 1])
        found.append(base[k] + t * n)
    if len(found) < 4:
        return None
    q = np.array(found) if undistort is None else undistort(np.array(found))
    mean = q.mean(axis=0)
    return mean, np.linalg.svd(q - mean)[2][0]


def refine_quad(
    gray: np.ndarray,
    corners: np.ndarray,
    half_width: float = 3.0,
    undistort: PixelMap | None = None,
) -> np.ndarray:
    """Sub-pixel refinement of a dark quad's corners on a light background.

    Along each edge, the intensity profile across the edge is sampled (bilinear) at points
    between 15 % and 85 % of its length; the mid-level crossing of each profile is an edge point
    (exact for an area-sampled step edge). A line fitted to each edge's points (total least
    squares) is intersected with its neighbours'.

    Args:
        gray: (H, W) uint8 image.
        corners: (4, 2) corners in order around the quad [px, OpenCV convention].
        half_width: half-length of the profiles [px]; capped at 30 % of the shortest edge
            divided by 8 (one AprilTag border cell is 1/8 of the edge).
        undistort: the lens's undistortion (:func:`undistort_pixels`), applied to the edge
            points before the line fits; ``None`` for a pinhole.

    Returns:
        (4, 2) refined corners (undistorted with ``undistort``), or the input corners (also
        undistorted) when refinement is not possible.
    """
    c = np.asarray(corners, dtype=float)
    fallback = c if undistort is None else undistort(c)
    edge_len = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
    hw = min(half_width, 0.3 * edge_len.min() / 8.0)
    if hw < 1.0:
        return fallback
    centre = c.mean(axis=0)
    steps = np.linspace(-hw, hw, round(8 * hw) + 1)
    img = gray.astype(np.float32)
    lines = []
    for j in range(4):
        line = _edge_line(img, c[j], c[(j + 1) % 4], edge_len[j], centre, steps, undistort)
        if line is None:
            return fallback
        lines.append(line)
    out = np.empty((4, 2))
    for j in range(4):  # corner j is the meeting point of edges j-1 and j
        (m0, d0), (m1, d1) = lines[j - 1], lines[j]
        A = np.column_stack([d0, -d1])
        if abs(np.linalg.det(A)) < 1e-6:
            return fallback
        s = np.linalg.solve(A, m1 - m0)
        out[j] = m0 + s[0] * d0
    if np.max(np.abs(out - fallback)) > 2.0:  # refinement wandered off: the detector's corners
        return fallback
    return out


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
    ) -> None:
        if not tag_size > 0:
            raise ValueError(f"tag_size must be > 0 m, got {tag_size}")
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
        self.refine_corners = bool(refine_corners)
        self.distortion: tuple[float, ...] | None = None
        if distortion is not None and np.any(np.asarray(distortion, dtype=float) != 0):
            if len(distortion) != 4:
                raise ValueError(f"distortion must be (k1, k2, p1, p2), got {distortion}")
            self.distortion = tuple(float(c) for c in distortion)

    def _undistort(self, pixels: np.ndarray) -> np.ndarray:
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
        K = self.intrinsics
        params = (K.fx, K.fy, K.cx + APRILTAG_PIXEL_OFFSET, K.cy + APRILTAG_PIXEL_OFFSET)
        found = [
            d
            for d in self._detector.detect(np.ascontiguousarray(gray), True, params, self.tag_size)
            if d.tag_id == self.tag_id
        ]
        if not found:
            return None
        det = max(found, key=lambda d: d.decision_margin)
        corners = np.asarray(det.corners, dtype=float) - APRILTAG_PIXEL_OFFSET
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
            if T_try[2, 3] <= 0 or not np.all(np.isfinite(T_try)):
                continue
            e = project_points(self.intrinsics, T_try, self._object_points) - corners
            err = float(np.sum(e**2))
            if err < best_err:
                best, best_err = T_try, err
        return best
