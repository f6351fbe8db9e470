"""The controllers' common interface: reset at the start pose, command at each control tick.

Before a run the runner lets a controller learn its task by being shown (:meth:`Controller.
teach`, teach-by-showing): the experimenters place the real robot at a pose and the controller
records what the sensors measure there — a measurement, never the pose's truth.

A controller also describes its own task to the runner — its goal pose, the checkpoints at
which the run records where the platform is, its extra summary fields and how a run that
ran out of time ended — so the runner needs no knowledge of any controller.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.options import NoOptions
from cdpr_twin.types import Command, Measurement, PoseEstimate, Status, TagDetection


@dataclass(frozen=True, eq=False)
class RunEnd:
    """What a run's end looks like, for a controller's summary fields (metrics only).

    Attributes:
        status: how the run ended.
        last_tag: the last tag detection of the run, or ``None``.
        true_tag_error: ground-truth distance of the final tag view to :attr:`Controller.
            goal_view` (``translation_m``, ``rotation_deg``), computed by the runner; ``None``
            without a goal view, camera or tag. The controller sees this error, never truth.
        last_tag_time: when ``last_tag`` was read [s] (``None``: no detection, or not known).
    """

    status: str
    last_tag: TagDetection | None
    true_tag_error: dict | None
    last_tag_time: float | None = None


class Controller(ABC):
    """A controller at a fixed rate; it sees only measurements, estimates and the nominal model.

    Subclasses set ``name`` and ``Options`` and are registered with
    :func:`cdpr_twin.plugins.register`.

    Args:
        geometry: the nominal robot geometry.
        options: an instance of the class's ``Options`` (defaults when ``None``).
    """

    kind: ClassVar[str] = "controller"
    name: ClassVar[str] = ""
    Options: ClassVar[type] = NoOptions
    needs_camera: ClassVar[bool] = False
    """Whether the controller needs tag detections (the scenario refuses it without camera)."""
    timeout_status: ClassVar[Status] = Status.COMPLETED
    """The run's status when its duration ends before the controller is done."""

    def __init__(self, geometry: CdprGeometry, options: Any = None) -> None:
        self.geometry = geometry
        self.options = self.Options() if options is None else options

    def check(self) -> None:  # noqa: B027  (optional hook: nothing to check by default)
        """Check the task against the nominal robot before a run starts.

        Raises:
            cdpr_twin.options.OptionError: naming the option at fault.
        """

    def check_period(self, period: float) -> None:  # noqa: B027  (optional hook)
        """Check the task against the control period [s] it will run at, before a run starts.

        Raises:
            cdpr_twin.options.OptionError: naming the option at fault.
        """

    def teach(self, show: Callable[[np.ndarray], Measurement]) -> None:  # noqa: B027
        """Learn the task by being shown, once before the run (optional hook: nothing to learn).

        The runner calls it after :meth:`check`, before the robot is homed at the start pose and
        :meth:`reset` is called; what it learns survives :meth:`reset`.

        Args:
            show: ``show(T_base_platform)`` places the true robot at a platform pose (4, 4), lets
                it settle, and returns what the sensors measure there.

        Raises:
            cdpr_twin.options.OptionError: naming the option at fault (e.g. the tag is not seen
                at the pose shown).
        """

    @abstractmethod
    def reset(self, T_base_platform0: np.ndarray) -> None:
        """Start a task from a known platform pose."""

    @abstractmethod
    def command(
        self, t: float, period: float, estimate: PoseEstimate, measurement: Measurement
    ) -> Command:
        """The command for the control period [t, t + period].

        Args:
            t: current time [s].
            period: control period [s].
            estimate: the in-loop estimator's current estimate.
            measurement: the current measurement (PBVS reads its tag detection).
        """

    @property
    def goal_is_taught(self) -> bool:
        """Whether :meth:`teach` sets the goal: known only once the true robot is shown.

        A check before any robot is built (the scenario's preflight) then leaves the goal to
        the run, which checks the view it was shown.
        """
        return False

    def planned_pose(self, t: float) -> np.ndarray | None:
        """The pose the controller plans for time t, if it plans one (else ``None``)."""
        return None

    def goal_pose(self, T_base_tag: np.ndarray | None) -> np.ndarray | None:
        """The platform pose the task should end at, for the summary (else ``None``).

        Args:
            T_base_tag: (4, 4) the tag pose the nominal model states, or ``None``.
        """
        return None

    @property
    def goal_view(self) -> np.ndarray | None:
        """(4, 4) the tag pose in the camera frame the task should end at, if it has one."""
        return None

    def checkpoints(self, duration: float) -> list[tuple[float, np.ndarray]]:
        """Times [s] and poses at which the run records where the platform is.

        E.g. the ends of trajectory segments, within a run of ``duration`` seconds.
        """
        return []

    def summary(self, end: RunEnd) -> dict[str, Any]:
        """Extra top-level fields of ``summary.json`` (none by default)."""
        return {}
