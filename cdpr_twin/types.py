"""Values that cross layers (numpy only): sensors → estimators → controllers → winches.

Importing this module loads neither MuJoCo, OpenCV nor pupil-apriltags, so estimators and
controllers built on it run on a real robot's logs as well as on the twin's.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass, field

import numpy as np

from cdpr_twin.math.se3 import pose_distance, rot_x, transform

T_TAGPUPIL_TAGVISP = transform(rot_x(np.pi), np.zeros(3))
"""ViSP's tag frame (z out of the tag, y up; the paper's ᶜp_o) in pupil-apriltags' tag frame
(z into the tag, y down): ``T_cam_tagViSP = T_cam_tagPupil @ T_TAGPUPIL_TAGVISP``. A rotation by
π about x, its own inverse: ``T_cam_tagPupil = T_cam_tagViSP @ T_TAGPUPIL_TAGVISP`` as well."""


def _frozen(value: object, dtype: type | None = None) -> np.ndarray:
    out = np.array(value, dtype=dtype)
    # (setflags: cheaper than assigning flags.writeable, and values are made every tick)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in the OpenCV convention.

    Attributes:
        width: image width [px].
        height: image height [px].
        fx: focal length along x [px].
        fy: focal length along y [px].
        cx: principal point x [px] (OpenCV: top-left pixel centre at 0).
        cy: principal point y [px].
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_fovy(cls, width: int, height: int, fovy: float) -> CameraIntrinsics:
        """Intrinsics of an ideal symmetric frustum with square pixels (MuJoCo's cameras).

        Args:
            width: image width [px].
            height: image height [px].
            fovy: vertical field of view [rad].
        """
        f = 0.5 * height / np.tan(0.5 * fovy)
        return cls(width, height, f, f, 0.5 * width - 0.5, 0.5 * height - 0.5)

    def scaled(self, factor: int) -> CameraIntrinsics:
        """The same camera sampled ``factor`` times finer in each direction.

        Pixel (u, v) covers [u − ½, u + ½] (OpenCV's centres at integers); the finer image
        covers the same area with ``factor`` × ``factor`` pixels, so u' = factor·(u + ½) − ½.
        """
        s = int(factor)
        if s == 1:
            return self
        return CameraIntrinsics(
            self.width * s,
            self.height * s,
            self.fx * s,
            self.fy * s,
            s * (self.cx + 0.5) - 0.5,
            s * (self.cy + 0.5) - 0.5,
        )

    def widened(self, mx: int, my: int) -> CameraIntrinsics:
        """The same camera with ``mx`` more pixels left and right, ``my`` above and below.

        The focal length and the pixel grid stay; the principal point moves with the origin:
        the widened image's pixel (u + mx, v + my) is this one's (u, v).
        """
        if not (mx or my):
            return self
        return CameraIntrinsics(
            self.width + 2 * mx, self.height + 2 * my, self.fx, self.fy, self.cx + mx, self.cy + my
        )

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class TagDetection:
    """One detected AprilTag.

    Attributes:
        tag_id: the tag's id in its family.
        corners: (4, 2) corners [px, OpenCV convention] in pupil-apriltags' order: the tag
            frame's (−s/2, s/2), (s/2, s/2), (s/2, −s/2), (−s/2, −s/2) (counter-clockwise in the
            image, starting bottom-left of the upright tag).
        T_cam_tag: (4, 4) tag pose in the camera frame (pupil-apriltags' tag frame).
        decision_margin: pupil-apriltags' decoding margin (higher is more certain).
        reprojection_error: RMS corner reprojection error of ``T_cam_tag`` [px].
    """

    tag_id: int
    corners: np.ndarray
    T_cam_tag: np.ndarray
    decision_margin: float
    reprojection_error: float


class Status(enum.StrEnum):
    """What a controller reports at each tick, and how a run ended (``summary.json``)."""

    START = "start"
    """The row recorded at the start pose, before any command."""
    TRACKING = "tracking"
    """Open loop: following the trajectory."""
    DONE = "done"
    """Open loop: the trajectory's last period was commanded."""
    COMPLETED = "completed"
    """Open loop: the run's duration ended before the trajectory did."""
    SERVOING = "servoing"
    """PBVS: moving toward the goal view."""
    SATURATED = "saturated"
    """PBVS: moving, with the speed capped."""
    TAG_LOST = "tag_lost"
    """PBVS: no tag detection, zero velocity commanded."""
    CONVERGED = "converged"
    """PBVS: the feature error is below the convergence thresholds."""
    TIME_LIMIT = "time_limit"
    """PBVS: the run's duration ended before convergence."""
    INTERRUPTED = "interrupted"
    """The run was stopped by Ctrl-C."""
    TERMINATED = "terminated"
    """The run was stopped by SIGTERM (a CI timeout, ``docker stop``)."""


@dataclass(frozen=True, eq=False)
class Command:
    """What a controller asks of the winches for the next control period.

    Attributes:
        cable_rates: (m,) winch rates l̇ [m/s].
        twist_platform: (6,) the platform twist ᵖv_p = [v, ω] these rates realise (in F_p,
            about the platform origin) [m/s, rad/s]; the control-based estimator integrates it.
        done: the task is finished (trajectory ended, or servo converged).
        status: what the controller is doing.
        error: (6,) task error when the controller has one (PBVS: e = s − s*), else ``None``.
    """

    cable_rates: np.ndarray
    twist_platform: np.ndarray
    done: bool = False
    status: Status = Status.TRACKING
    error: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("cable_rates", "twist_platform", "error"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _frozen(value, float))
        if self.twist_platform.shape != (6,):
            raise ValueError(
                f"Command.twist_platform must be (6,) [v, ω] of the platform, got shape "
                f"{self.twist_platform.shape}"
            )


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """One estimate of the platform pose.

    Attributes:
        time: time of the measurement it comes from [s].
        T_base_platform: (4, 4) estimated pose (the last valid one when ``valid`` is False).
        valid: whether this update produced a new estimate from its inputs.
        flags: why not, or what is special (the constants of :mod:`cdpr_twin.estimators.base`).
        cables: indices (from 0) of the cables used, for model-based estimators.
        residual: largest |model length − measured length| over the cables used [m].
        iterations: solver iterations.
        covariance: (6, 6) covariance of the pose error δ in ``T_true = T_est · exp(δ)``,
            δ = [v, ω] in F_p [m², m·rad, rad²]; ``None`` when the estimator gives none.
    """

    time: float
    T_base_platform: np.ndarray
    valid: bool = True
    flags: frozenset[str] = field(default_factory=frozenset)
    cables: tuple[int, ...] = ()
    residual: float = 0.0
    iterations: int = 0
    covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        # (the freezing inline: six estimates a tick)
        T = np.array(self.T_base_platform, dtype=float)
        T.setflags(write=False)
        object.__setattr__(self, "T_base_platform", T)
        if not isinstance(self.flags, frozenset):
            object.__setattr__(self, "flags", frozenset(self.flags))
        if self.covariance is not None:
            cov = _frozen(self.covariance, float)
            if cov.shape != (6, 6):
                raise ValueError(f"PoseEstimate.covariance must be (6, 6), got {cov.shape}")
            object.__setattr__(self, "covariance", cov)


@dataclass(frozen=True, eq=False)
class Measurement:
    """What the robot's sensors report at one instant: the only input of estimators.

    Ground truth is not here: the runner reads it from the physics for metrics and recording
    only, so no estimator or controller can see it.

    Attributes:
        time: time of the reading [s].
        cable_lengths: (m,) encoder readings: each winch's unstretched paid-out length l0_i,
            homed at the start pose to the nominal model's value there [m].
        tensions: (m,) tension-sensor readings at B_i, noise included [N].
        command: the last command sent to the winches (``None`` before the first).
        image: (H, W, 3) RGB uint8 frame of the onboard camera, or ``None`` (no camera).
        tag: the tag detected in ``image``, or ``None`` (no camera, or tag not found).
        tensions_clipped: (m,) bool, which tension readings sit at a limit of the sensor's
            range (the true tension may be beyond it), or ``None`` when readings never clip.
    """

    time: float
    cable_lengths: np.ndarray
    tensions: np.ndarray
    command: Command | None = None
    image: np.ndarray | None = None
    tag: TagDetection | None = None
    tensions_clipped: np.ndarray | None = None

    def __post_init__(self) -> None:
        # readings as floats whatever a log held (ints, float32): estimators compute on float64
        for name in ("cable_lengths", "tensions"):
            object.__setattr__(self, name, _frozen(getattr(self, name), float))
        for name in ("image", "tensions_clipped"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _frozen(value))

    @property
    def n_cables(self) -> int:
        """Number of cables m."""
        return len(self.cable_lengths)

    @property
    def cable_rates(self) -> np.ndarray:
        """(m,) winch rates of the last command [m/s] (zeros before the first)."""
        if self.command is None:
            return np.zeros(self.n_cables)
        return np.asarray(self.command.cable_rates)

    @property
    def twist_platform(self) -> np.ndarray | None:
        """(6,) platform twist of the last command, or ``None`` before the first."""
        return None if self.command is None else np.asarray(self.command.twist_platform)

    @property
    def camera_on(self) -> bool:
        """Whether this measurement carries a camera frame."""
        return self.image is not None


@dataclass(frozen=True, eq=False)
class TickRecord:
    """One control tick of a run, as it happened: what every sink records.

    Ground truth sits beside what the robot's software saw (``measurement``, ``estimates``,
    ``command``), never inside it: sinks (the time series, the Rerun recording, the metrics,
    the summary) read both, estimators and controllers only ever get the latter.

    Attributes:
        time: simulation time of the tick's read [s].
        measurement: what the sensors read.
        estimates: every estimator's estimate, by name, in recording order.
        command: the command that led to this tick, or ``None`` at the start (tick 0).
        plan: (4, 4) the pose the controller plans for ``time``, or ``None``.
        T_base_platform: (4, 4) the true platform pose.
        tensions: (m,) the true cable tensions [N].
        T_cam_tag: (4, 4) the true tag pose in the camera frame, when asked for, else ``None``.
        events: the scenario's events fired during the tick (since the last tick's read):
            (simulation time [s], event, ``"start"`` or ``"end"``) each.
        faults: the faults the robot's monitor saw during the tick
            (:class:`cdpr_twin.sim.Fault` each), in time order.
        stop: the run status the first fault ends the run with (``[monitor] on_fault =
            "stop"``), or ``None``: the run goes on.
    """

    time: float
    measurement: Measurement
    estimates: dict[str, PoseEstimate]
    command: Command | None
    plan: np.ndarray | None
    T_base_platform: np.ndarray
    tensions: np.ndarray
    T_cam_tag: np.ndarray | None
    events: tuple = ()
    faults: tuple = ()
    stop: str | None = None

    @functools.cached_property
    def deviations(self) -> dict[str, tuple[float, float]]:
        """Each estimator's distance from the true pose (translation [m], rotation [rad]), by name.

        Computed when first asked for: the run's metrics and recording compute theirs a batch of
        ticks at a time, and a Gymnasium step or a calibration's reading needs none.
        """
        if not self.estimates:  # (a calibration's episode runs no estimator)
            return {}
        T_est = np.array([e.T_base_platform for e in self.estimates.values()])
        dts, drs = pose_distance(T_est, self.T_base_platform)
        return dict(zip(self.estimates, zip(dts.tolist(), drs.tolist(), strict=True), strict=True))

    @property
    def marks(self) -> tuple[str, ...]:
        """What happened during the tick, in words: the events, then the faults."""
        return tuple(e.describe(phase) for _, e, phase in self.events) + tuple(
            f.described for f in self.faults
        )
