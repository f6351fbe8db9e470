"""The controllers' common interface: reset at the start pose, command at each control tick."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from cdpr_twin.estimators.base import PoseEstimate
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.measurement import Measurement


@dataclass(frozen=True, eq=False)
class Command:
    """What a controller asks of the winches for the next control period.

    Attributes:
        cable_rates: (m,) winch rates l̇ [m/s].
        twist_platform: (6,) the platform twist ᵖv_p = [v, ω] these rates realise (in F_p,
            about the platform origin) [m/s, rad/s]; the control-based estimator integrates it.
        done: the task is finished (trajectory ended, or servo converged).
        status: short machine-readable state (``"tracking"``, ``"converged"``, ``"tag_lost"``…).
        error: (6,) task error when the controller has one (PBVS: e = s − s*), else ``None``.
    """

    cable_rates: np.ndarray
    twist_platform: np.ndarray
    done: bool = False
    status: str = ""
    error: np.ndarray | None = None


class Controller(ABC):
    """A controller at a fixed rate; it sees only measurements, estimates and the nominal model.

    Args:
        geometry: the nominal robot geometry.
    """

    name: str = ""

    def __init__(self, geometry: CdprGeometry) -> None:
        self.geometry = geometry

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

    def planned_pose(self, t: float) -> np.ndarray | None:
        """The pose the controller plans for time t, if it plans one (else ``None``)."""
        return None
