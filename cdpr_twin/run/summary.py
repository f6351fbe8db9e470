"""What a run keeps beyond its metrics for ``summary.json``, and the summary itself.

Truth stays here and in :mod:`cdpr_twin.run.metrics`: the controller's summary fields get only the
error of its goal view, never a true pose.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cdpr_twin.controllers.base import RunEnd
from cdpr_twin.math.se3 import pose_error
from cdpr_twin.run.metrics import RunMetrics, run_summary
from cdpr_twin.types import TagDetection, TickRecord


@dataclass
class Tally:
    """What the run keeps from its measurements for the summary.

    Attributes:
        last_tag: the last tag detection after a command, or ``None``.
        last_tag_time: the time of the read that delivered it [s], or ``None``.
        clipped: (m,) clipped tension readings per cable (every read of the run, t = 0
            included), or ``None`` (the sensors never clip).
        faults: the robot's faults (:class:`cdpr_twin.sim.Fault`), in time order.
        truth: the true state at the last recorded tick (``time`` [s], ``T_base_platform``
            (4, 4), ``tensions`` (m,) [N], ``T_cam_tag`` (4, 4) or ``None``), or ``None``
            before the first. The summary is of that tick, not of a physics state a stop
            (Ctrl-C, SIGTERM, a failure) left mid-tick, which no file recorded.
        events: how many events had fired by that tick (later ones: not reached).
    """

    last_tag: TagDetection | None = None
    last_tag_time: float | None = None
    clipped: np.ndarray | None = None
    faults: list = dataclasses.field(default_factory=list)
    truth: dict | None = None
    events: int | None = None

    def add(self, tick: TickRecord) -> None:
        """Keep what the summary needs of the tick just recorded."""
        m = tick.measurement
        if m.tensions_clipped is not None:
            if self.clipped is None:
                self.clipped = np.zeros(len(m.tensions_clipped), dtype=int)
            self.clipped += m.tensions_clipped
        if tick.command is not None and m.tag is not None:  # a detection after a command
            self.last_tag, self.last_tag_time = m.tag, float(m.time)
        self.truth = {
            "time": tick.time,
            "T_base_platform": tick.T_base_platform,
            "tensions": tick.tensions,
            "T_cam_tag": tick.T_cam_tag,
        }
        self.events = (self.events or 0) + len(tick.events)
        self.faults += tick.faults


def summarize(setup, metrics: RunMetrics, status: str, tally: Tally) -> dict:
    """The content of ``summary.json`` for a run that ended with ``status``.

    Args:
        setup: the run's :class:`~cdpr_twin.run.runner.RunSetup`.
        metrics: its metrics.
        status: how it ended.
        tally: what it kept from its measurements and monitor.
    """
    p, view = setup.physics, setup.controller.goal_view
    if view is not None and setup.shown_view is not None:
        view = setup.shown_view  # a taught view: what the camera truly saw when shown
    truth, recorded = tally.truth, tally.events
    if truth is None:  # stopped before its first tick was recorded: the state now
        T_cam_tag = p.T_cam_tag if tag_view(setup) else None
        truth = {
            "time": p.time,
            "T_base_platform": p.T_base_platform,
            "tensions": p.tensions,
            "T_cam_tag": T_cam_tag,
        }
        recorded = len(setup.events.fired)
    true_tag_error = None
    if view is not None and truth["T_cam_tag"] is not None:  # truth stays here: the error only
        true_tag_error = pose_error(truth["T_cam_tag"], view)
    end = RunEnd(status, tally.last_tag, true_tag_error, tally.last_tag_time)
    extra = setup.controller.summary(end)
    out = run_summary(setup.scenario, status, metrics, truth, setup.goal_pose, extra)
    if setup.homing_offset is not None:
        off = setup.homing_offset
        out["homing_offset"] = {
            "position_m": off[:3].tolist(),
            "rotation_deg": np.degrees(off[3:]).tolist(),
        }
    if tally.clipped is not None:
        out["tension_clipped_readings"] = tally.clipped.tolist()
    fired, later = setup.events.fired[:recorded], setup.events.fired[recorded:]
    if fired:
        out["events"] = [e.as_dict(t, phase) for t, e, phase in fired]
    # fired after the last recorded tick (a stop's): not reached, as far as the files go
    late = [
        {"due_s": t, "kind": e.kind, "phase": phase, "at": e.at} | e.fields()
        for t, e, phase in later
    ]
    if pending := late + setup.events.pending:  # the run ended first: said, not dropped
        out["events_not_reached"] = pending
    if tally.faults:
        out["faults"] = [f.as_dict() for f in tally.faults]
    return out


def tag_view(setup) -> bool:
    """Whether the summary needs the true tag pose (a goal view, a camera and a tag)."""
    p = setup.physics
    return setup.controller.goal_view is not None and p.has_camera and p.has_tag
