"""One run's control loop, one tick at a time: the only place that says what a tick does.

An :class:`Episode` owns a prepared run (:class:`~cdpr_twin.run.runner.RunSetup`). Its
:meth:`~Episode.reset` puts the robot at its start and records tick 0; each
:meth:`~Episode.step` is one control tick::

    command = controller.command(...)     # or the caller's: a policy, a calibration's tour
    physics.advance(period, rates)        # events and the monitor act between physics steps
    m = sensors.read(command)             # encoders, tensions, the tag
    estimates = setup.estimate(m)         # every estimator, inputs first
    tick = TickRecord(...)                # what happened, the truth beside it
    for sink in sinks: sink.add(tick)     # time series, Rerun, metrics, summary

A step's two halves are also there alone: :meth:`~Episode.advance` (the winches run, physics
steps, nothing is read) and :meth:`~Episode.read` (sense, estimate, record, without moving).
A calibration holds its readings with them: it reads, then rests a control period, and moves,
rests and tightens between its readings without reading.

The runner (:func:`cdpr_twin.run.runner.run`), the Gymnasium environment, campaign workers
(through the runner), the NEES study and the calibration's acquisition drive this object;
sinks only consume the :class:`~cdpr_twin.types.TickRecord` it returns.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from cdpr_twin.estimators.base import SensorWatches
from cdpr_twin.run.homing_and_teaching import home_by_drums
from cdpr_twin.run.interrupts import shielded
from cdpr_twin.types import Command, Measurement, PoseEstimate, TickRecord


class TickSink(Protocol):
    """Something that records each tick (it reads the record, changes nothing of the run)."""

    def add(self, tick: TickRecord) -> None:
        """Record one tick."""
        ...


class Episode:
    """A run of a prepared scenario, one control tick per :meth:`step`.

    Args:
        setup: the prepared run (:class:`~cdpr_twin.run.runner.RunSetup`).
        sinks: where each tick goes, in this order (a stop waits until every one has it).
        true_tag_view: also keep the true tag pose in the camera frame in each record.
    """

    def __init__(self, setup, sinks: Sequence[TickSink] = (), true_tag_view: bool = False):
        self.setup, self.sinks, self.true_tag_view = setup, tuple(sinks), true_tag_view
        self.period = setup.scenario.model.control_period
        self.ticks = 0
        """Control ticks stepped since :meth:`reset` (tick 0, the start, not counted)."""
        self.last: TickRecord | None = None
        """The last tick recorded, or ``None`` before :meth:`reset`."""

    def reset(self) -> TickRecord:
        """Put the robot at its start, read and estimate there: tick 0 (no command yet).

        The true platform settles at the start pose moved by this run's homing offset; the
        encoders are homed, and the controller and estimators reset, at the nominal start pose
        (:func:`start`). Events due at t = 0 act before the first read.
        """
        start(self.setup)
        self.ticks = 0
        return self.read()

    def step(self, command: Command | None = None) -> TickRecord:
        """One control tick: command, actuate and simulate, sense, estimate, record.

        Args:
            command: the winch command for this tick; ``None``: the scenario's controller
                decides it from the last tick's in-loop estimate and measurement.

        Returns:
            The tick's record (also given to every sink).

        Raises:
            ValueError: the command's rates are refused by the winches (the state unchanged),
                or no command is given to an episode without a controller.
            SimulationError: the simulation diverged.
        """
        setup, last = self.setup, self.last
        if command is None:
            if setup.controller is None:
                raise ValueError("this episode has no controller: pass each tick's command")
            assert last is not None, "call reset() before step()"
            in_loop = last.estimates[setup.scenario.estimators.in_loop]
            command = setup.controller.command(
                self.ticks * self.period, self.period, in_loop, last.measurement
            )
        # the winches run for one period; events and the monitor act between physics steps
        self.advance(self.period, command.cable_rates)
        self.ticks += 1
        return self.read(command)

    def advance(self, duration: float, cable_rates) -> None:
        """Run the winches at ``cable_rates`` for ``duration`` with nothing read.

        The first half of :meth:`step`; alone, the robot moving or resting between readings
        that are not control ticks (a calibration's moves, rests and tightening).

        Args:
            duration: how long [s]; a whole number of physics steps.
            cable_rates: (m,) winch rates dl0/dt [m/s] (positive pays cable out).

        Raises:
            ValueError: the rates or duration are refused (the state unchanged).
            SimulationError: the simulation diverged.
        """
        # events and the monitor act inside, between physics steps (their hooks)
        self.setup.physics.advance(duration, cable_rates)

    def read(self, command: Command | None = None, render: bool | None = None) -> TickRecord:
        """Sense, estimate and record now, without moving: the second half of :meth:`step`.

        Events due now act first (a hook fires before a physics chunk, so what is due at the
        end of the last one has not acted yet).

        Args:
            command: the command that led here (carried in the measurement), or ``None``.
            render: read the camera; ``None``: when the sensors have it on.

        Returns:
            The record (also given to every sink).
        """
        setup, physics = self.setup, self.setup.physics
        setup.events.fire(physics.time + 0.5 * physics.timestep)
        m = setup.sensors.read(command, render)
        return self._record(m, setup.estimate(m), command)

    def _record(
        self, m: Measurement, estimates: dict[str, PoseEstimate], command: Command | None
    ) -> TickRecord:
        """What happened during the tick, beside the truth; given to every sink."""
        setup, physics = self.setup, self.setup.physics
        # (a plugin's code: outside the shield)
        plan = None if setup.controller is None else setup.controller.planned_pose(m.time)
        events = tuple(setup.events.take())
        faults = ()
        if setup.monitor is not None:
            # its last look, at the state the tick's last physics chunk left (after the read:
            # a MuJoCo warning the camera's rendering raised belongs to this tick too)
            setup.monitor.check()
            faults = tuple(setup.monitor.take())
        stop = None
        if faults and setup.scenario.monitor.on_fault == "stop":
            stop = faults[0].status
        tick = TickRecord(
            time=m.time,
            measurement=m,
            estimates=estimates,
            command=command,
            plan=plan,
            T_base_platform=physics.T_base_platform,
            tensions=physics.tensions,
            T_cam_tag=physics.T_cam_tag if self.true_tag_view else None,
            events=events,
            faults=faults,
            stop=stop,
        )
        self.last = tick
        if self.sinks:
            # a stop waits until the tick is in every sink (metrics, files, summary)
            with shielded(escape=True):
                for sink in self.sinks:
                    sink.add(tick)
        return tick


def start(setup) -> None:
    """Put the robot at its start and everything that believes in it at the nominal start.

    The true platform settles at ``setup.true_start`` (the start pose moved by the homing
    offset); the encoders are homed, and the controller and estimators reset, at the
    scenario's nominal start pose. With each drum homed on its own
    (``setup.drum_zero_errors``), the platform settles instead where the cables, wound to the
    nominal start's lengths from their erring zeros, hold it
    (:func:`~cdpr_twin.run.homing_and_teaching.home_by_drums`).

    Args:
        setup: the prepared run (:class:`~cdpr_twin.run.runner.RunSetup`).
    """
    s = setup.scenario
    if setup.drum_zero_errors is not None:  # each drum homed on its own: settle where held
        home_by_drums(s, setup.physics, setup.sensors, setup.nominal, setup.drum_zero_errors)
    else:
        setup.physics.reset(s.start_pose if setup.true_start is None else setup.true_start)
        setup.sensors.home(s.start_pose)
    if setup.controller is not None:
        setup.controller.reset(s.start_pose)
    # reset together and fed the same measurements: one set of sensor watches serves them all
    watches = SensorWatches()
    for est in setup.estimators.values():
        est.reset(s.start_pose, 0.0)
        est.share_watches(watches)
    if setup.monitor is not None:
        setup.monitor.reset()
