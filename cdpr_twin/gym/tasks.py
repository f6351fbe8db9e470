"""What an environment episode asks for: reward, success and horizon from the ground truth.

A task reads the truth (the reward of a simulated episode may: it is how a policy is scored,
not what it sees) and never the observation. Numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cdpr_twin.math.se3 import pose_distance, pose_from_vector
from cdpr_twin.types import T_TAGPUPIL_TAGVISP

P1 = (0.284, -0.197, 0.08, 0.0, 0.0, 0.0)
"""The paper's p1 ``[x, y, z, rx, ry, rz]`` (m, deg): the default goal of :class:`ReachPose`."""
GOAL_VIEW_VISP = (0.0, 0.0, 0.09, 180.0, 0.0, 180.0)
"""The paper's PBVS goal ᶜp_o1 (ViSP tag frame; m, deg): the default of :class:`ServoToTag`."""


@dataclass(frozen=True)
class Truth:
    """The ground truth a task is scored on (never part of an observation).

    Attributes:
        T_base_platform: (4, 4) true platform pose.
        T_cam_tag: (4, 4) true tag pose in the camera frame (pupil frame), or ``None``.
    """

    T_base_platform: np.ndarray
    T_cam_tag: np.ndarray | None


@dataclass(frozen=True)
class Score:
    """One step's score.

    Attributes:
        reward: −(translation error + rotation_weight · rotation error) of this step.
        success: the task is achieved (the episode terminates).
        translation_error: [m].
        rotation_error: [rad].
    """

    reward: float
    success: bool
    translation_error: float
    rotation_error: float


def _check_task(name: str, pose_key: str, pose, **positive: float) -> None:
    """A task's numbers, checked when it is made (not at its first step).

    Raises:
        ValueError: naming the field: a pose that is not 6 finite numbers, a tolerance or
            horizon that is not a finite number > 0, a weight < 0.
    """
    try:
        p = np.asarray(pose, dtype=float)
    except (TypeError, ValueError, OverflowError):
        p = np.full(1, np.nan)
    if p.shape != (6,) or not np.all(np.isfinite(p)) or np.asarray(pose).dtype == bool:
        raise ValueError(
            f"{name}: {pose_key} must be 6 finite numbers [x, y, z, rx, ry, rz] "
            f"(m, deg), got {pose!r}"
        )
    for key, value in positive.items():
        low = "≥ 0" if key == "rotation_weight" else "> 0"
        try:
            v = float(value)
        except (TypeError, ValueError, OverflowError):
            v = math.nan
        ok = math.isfinite(v) and not isinstance(value, bool | np.bool_)
        if not (ok and (v >= 0 if key == "rotation_weight" else v > 0)):
            raise ValueError(f"{name}: {key} must be a finite number {low}, got {value!r}")


@dataclass(frozen=True)
class ReachPose:
    """Bring the platform to a pose.

    Attributes:
        goal: ``[x, y, z, rx, ry, rz]`` (m, deg) in the base frame (default: the paper's p1).
        position_tolerance: success when the true platform is this close [m] …
        rotation_tolerance_deg: … and turned by less than this [deg].
        rotation_weight: metres of reward per radian of rotation error.
        horizon: episode length before truncation [s].
    """

    goal: tuple[float, ...] = P1
    position_tolerance: float = 0.002
    rotation_tolerance_deg: float = 0.2
    rotation_weight: float = 0.1
    horizon: float = 15.0
    name: ClassVar[str] = "reach"
    needs_camera: ClassVar[bool] = False

    def __post_init__(self) -> None:
        _check_task(
            "reach",
            "goal",
            self.goal,
            position_tolerance=self.position_tolerance,
            rotation_tolerance_deg=self.rotation_tolerance_deg,
            rotation_weight=self.rotation_weight,
            horizon=self.horizon,
        )

    @property
    def goal_pose(self) -> np.ndarray:
        """(4, 4) the goal ``T_base_platform``."""
        return pose_from_vector(self.goal)

    def score(self, truth: Truth) -> Score:
        """Score the true platform pose against the goal."""
        dt, dr = pose_distance(truth.T_base_platform, self.goal_pose)
        return _score(
            dt, dr, self.rotation_weight, self.position_tolerance, self.rotation_tolerance_deg
        )


@dataclass(frozen=True)
class ServoToTag:
    """Bring the camera to a view of the tag (the paper's PBVS task, §IV-C).

    Attributes:
        goal_view: the tag's pose in the camera frame, ``[x, y, z, rx, ry, rz]`` (m, deg),
            ViSP's tag frame as in the paper (default: ᶜp_o1).
        position_tolerance: success when the true view is this close [m] …
        rotation_tolerance_deg: … and turned by less than this [deg].
        rotation_weight: metres of reward per radian of rotation error.
        horizon: episode length before truncation [s].
    """

    goal_view: tuple[float, ...] = GOAL_VIEW_VISP
    position_tolerance: float = 0.001
    rotation_tolerance_deg: float = 0.2
    rotation_weight: float = 0.1
    horizon: float = 20.0
    name: ClassVar[str] = "servo"
    needs_camera: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _check_task(
            "servo",
            "goal_view",
            self.goal_view,
            position_tolerance=self.position_tolerance,
            rotation_tolerance_deg=self.rotation_tolerance_deg,
            rotation_weight=self.rotation_weight,
            horizon=self.horizon,
        )

    @property
    def goal_T_cam_tag(self) -> np.ndarray:
        """(4, 4) the goal view in pupil-apriltags' tag frame (the frame detections use)."""
        return pose_from_vector(self.goal_view) @ T_TAGPUPIL_TAGVISP

    def score(self, truth: Truth) -> Score:
        """Score the true view of the tag against the goal view."""
        if truth.T_cam_tag is None:
            raise ValueError("servo: the robot has no camera or no tag; use the reach task")
        dt, dr = pose_distance(truth.T_cam_tag, self.goal_T_cam_tag)
        return _score(
            dt, dr, self.rotation_weight, self.position_tolerance, self.rotation_tolerance_deg
        )


def _score(dt: float, dr: float, weight: float, tol: float, tol_deg: float) -> Score:
    success = bool(dt < tol and np.degrees(dr) < tol_deg)
    return Score(-(dt + weight * dr), success, dt, dr)


TASKS: dict[str, type[ReachPose] | type[ServoToTag]] = {"reach": ReachPose, "servo": ServoToTag}
"""The tasks by name."""


def make_task(task: str | ReachPose | ServoToTag) -> ReachPose | ServoToTag:
    """A task instance from a name (``"reach"``, ``"servo"``) or an instance.

    Raises:
        ValueError: for an unknown name, or an object that is not a task (a task has
            ``score(truth)``, ``horizon`` and ``needs_camera``).
    """
    if not isinstance(task, str):
        if not (
            callable(getattr(task, "score", None))
            and hasattr(task, "horizon")
            and hasattr(task, "needs_camera")
        ):
            raise ValueError(
                f"task must be {' or '.join(map(repr, TASKS))} or a task object (with score(), "
                f"horizon and needs_camera), got {task!r}"
            )
        return task
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {', '.join(TASKS)}")
    return TASKS[task]()
