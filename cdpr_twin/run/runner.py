"""The headless run: prepare a scenario, claim its outputs, drive its episode, save it all.

:func:`prepare` builds and checks everything a run needs (:class:`RunSetup`) before any output
is written; :func:`run` claims the output directory, then drives one
:class:`~cdpr_twin.run.episode.Episode` (where a control tick is spelled out: sense → estimate →
control → actuate → step → record) until the controller is done, a fault stops it or the time
is up, and completes the files as one transaction, whatever ended the run.

The runner knows no controller or estimator by name: each controller supplies its goal pose,
checkpoints, summary fields and the status of a run that ran out of time. Before the loop
(:func:`prepare`, :func:`~cdpr_twin.run.episode.start`): the controller may learn its task by
being shown a pose (teach-by-showing, :meth:`Controller.teach`); then the true robot is put at
the start pose moved by this run's homing offset (``[realism.homing]``), while the encoders are
homed, and the estimators and controller reset, at the *nominal* start pose.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cdpr_twin import plugins
from cdpr_twin.controllers.base import Controller
from cdpr_twin.estimators.base import Estimator, update_order
from cdpr_twin.files.transaction import OutputDir, OutputError, Terminated, others
from cdpr_twin.math.statics import InfeasibleTensionError
from cdpr_twin.options import OptionError
from cdpr_twin.recording.rerun import SceneInfo
from cdpr_twin.recording.sinks import Recorders
from cdpr_twin.run.episode import Episode, start
from cdpr_twin.run.homing_and_teaching import drum_zero_errors, homing, teach
from cdpr_twin.run.interrupts import held_here, interruption, shielded
from cdpr_twin.run.metrics import RunMetrics
from cdpr_twin.run.summary import Tally, summarize, tag_view
from cdpr_twin.scenario.loading import Scenario, ScenarioError
from cdpr_twin.scenario.preflight import check_goal, controller_for
from cdpr_twin.sim.events import EventSchedule, TagOcclusion
from cdpr_twin.types import Measurement, PoseEstimate, Status

if TYPE_CHECKING:
    from cdpr_twin.sim.monitor import Monitor
    from cdpr_twin.sim.physics import Physics
    from cdpr_twin.sim.sensors import NominalRobot, Sensors

__all__ = ["RunResult", "RunSetup", "prepare", "run", "start"]


@dataclass(kw_only=True)
class RunSetup:
    """Everything a run needs, built and validated before any output is written.

    Attributes:
        scenario: the scenario.
        physics: the simulated robot (:class:`cdpr_twin.sim.Physics`).
        sensors: its sensors (:class:`cdpr_twin.sim.Sensors`).
        nominal: what the robot's software believes (:class:`cdpr_twin.sim.NominalRobot`).
        estimators: by name, in recording order (the in-loop one first).
        order: the names in update order (inputs before the estimators that read them).
        controller: the controller, or ``None``: the caller commands every tick (a
            calibration's tour).
        goal_pose: (4, 4) the controller's goal, or ``None``.
        events: the scenario's timed events, hooked into the physics.
        monitor: the robot's plausibility monitor (:class:`cdpr_twin.sim.Monitor`), hooked
            into the physics, or ``None`` (``[monitor] enabled = false``).
        true_start: (4, 4) where the true platform starts: the start pose moved by the homing
            offset (truth: metrics and tests only).
        homing_offset: (6,) this run's homing offset [δp (m), δθ (rad)], or ``None`` (none).
        drum_zero_errors: (m,) this run's error of each drum's zero [m], or ``None``: the
            robot is homed by its pose (the start then settles where the cables hold it).
        shown_view: (4, 4) the true tag pose in the camera frame at the last pose shown to
            the controller (truth: the summary's true tag error only), or ``None``.
    """

    scenario: Scenario
    physics: Physics
    sensors: Sensors
    nominal: NominalRobot
    estimators: dict[str, Estimator]
    order: tuple[str, ...]
    controller: Controller | None
    goal_pose: np.ndarray | None
    events: EventSchedule
    monitor: Monitor | None = None
    true_start: np.ndarray | None = None
    homing_offset: np.ndarray | None = None
    drum_zero_errors: np.ndarray | None = None
    shown_view: np.ndarray | None = None

    def __post_init__(self) -> None:
        # each estimator's inputs read once: estimate() runs every tick, for every estimator
        ests = self.estimators
        self._plan = tuple((name, ests[name], ests[name].inputs) for name in self.order)
        # updated in recording order (the usual case): the estimates need no reordering
        self._reordered = self.order != tuple(ests)

    def estimate(self, m: Measurement) -> dict[str, PoseEstimate]:
        """Update every estimator (in dependency order); returns estimates in recording order."""
        out: dict[str, PoseEstimate] = {}
        # loops, not comprehensions: this runs every tick, for every estimator
        for name, est, needs in self._plan:
            if needs:
                inputs = {}
                for n in needs:
                    inputs[n] = out[n]
                out[name] = est.update(m, inputs)
            else:
                out[name] = est.update(m)
        if not self._reordered:
            return out
        recorded: dict[str, PoseEstimate] = {}
        for name in self.estimators:
            recorded[name] = out[name]
        return recorded

    @property
    def cov(self) -> tuple[str, ...]:
        """The estimators whose estimates carry a covariance (recorded with them)."""
        return tuple(n for n, e in self.estimators.items() if e.reports_covariance)

    def close(self) -> None:
        """Free the renderer; drop the physics' hooks (their cycle kept the model alive)."""
        self.sensors.close()
        self.physics.clear_hooks()


@dataclass(frozen=True)
class RunResult:
    """What :func:`run` returns.

    Attributes:
        summary: the content of ``summary.json``.
        wall_time: seconds of wall-clock time the loop took.
        out_dir: where the outputs are, or ``None``.
    """

    summary: dict
    wall_time: float
    out_dir: Path | None

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.summary["simulated_time_s"] / max(self.wall_time, 1e-9)


def _update_order(estimators: dict[str, Estimator], s: Scenario) -> tuple[str, ...]:
    dropped = frozenset(s.overrides.get("dropped_estimators", ()))
    try:
        return update_order(estimators, dropped)
    except ValueError as exc:
        raise ScenarioError(f"{s.source}: estimators: {exc}") from None


def _build_plugins(scenario: Scenario, nominal) -> tuple[Controller, dict[str, Estimator]]:
    src, geom = scenario.source, nominal.geometry
    controller = controller_for(scenario, nominal)
    estimators = {}
    for name in scenario.estimators.names:
        est_cls = plugins.lookup("estimator", name)
        options = scenario.estimators.options.get(name) or est_cls.Options()
        try:
            estimators[name] = est_cls(geom, options)
        except (Exception, SystemExit) as exc:  # SystemExit: a plugin's sys.exit()
            raise ScenarioError(f"{src}: estimators.{name}: {type(exc).__name__}: {exc}") from None
    return controller, estimators


def prepare(scenario: Scenario) -> RunSetup:
    """Build the robot, its sensors, the estimators and controller; check everything.

    Raises:
        ScenarioError: naming the file and field at fault.
    """
    from cdpr_twin.sim import ModelError, Sensors, SimulationError, build_robot  # MuJoCo's door

    s, src = scenario, scenario.source
    try:
        occluder = any(isinstance(e, TagOcclusion) for e in s.events)
        built = build_robot(
            s.model.file,
            s.truth,
            s.model.timestep,
            s.model.align_every,
            s.realism.winch,
            occluder,
            s.model.nominal,
            (s.model.payload, s.model.payload_com),
            drive=s.realism.drive,
            cable=s.realism.cable,
            pulley=s.realism.pulley,
        )
        physics, nominal = built.physics, built.nominal
        sensors = Sensors(
            physics,
            nominal,
            s.sensors.tension_noise_std,
            s.seed,
            camera=s.sensors.camera,
            realism=s.realism,
            robot_seed=s.truth.seed,
            period=s.model.control_period,
            tag_window=s.sensors.tag_window,
        )
    except ModelError as exc:
        raise ScenarioError(f"{src}: {exc.field}: {exc}") from None
    except SimulationError as exc:
        raise ScenarioError(f"{src}: sensors.camera: {exc}") from None
    except OptionError as exc:
        if not exc.field.startswith("realism."):
            raise ScenarioError(f"{src}: model: {exc}") from None
        raise ScenarioError(f"{src}: {exc.field}: {exc.problem}") from None
    except ValueError as exc:
        raise ScenarioError(f"{src}: model: {exc}") from None
    try:
        return _assemble(s, physics, sensors, nominal)
    except BaseException:  # nothing outlives a refused scenario: free the renderer
        sensors.close()
        raise


def _assemble(s: Scenario, physics, sensors, nominal) -> RunSetup:
    src = s.source
    offset, true_start = homing(s)
    try:
        physics.reset(true_start, settle_time=0.0)
    except (ValueError, InfeasibleTensionError) as exc:
        where = "start.pose" if offset is None else "start.pose (moved by its homing offset)"
        raise ScenarioError(f"{src}: {where}: {exc}") from None
    for i, event in enumerate(s.events):  # in file order, as the file numbers them
        try:
            event.check(physics.n_cables)
        except OptionError as exc:
            raise ScenarioError(f"{src}: events[{i}].{exc.field}: {exc.problem}") from None
    controller, estimators = _build_plugins(s, nominal)
    order = _update_order(estimators, s)
    shown_view = teach(s, physics, sensors, controller)  # before events can act
    events = EventSchedule(s.events, physics, sensors)
    if s.events:  # no hook, no per-chunk cost, when nothing is scheduled
        physics.add_hook(events)
    monitor = _monitor(s, physics)
    goal = controller.goal_pose(nominal.T_base_tag)
    if goal is not None and shown_view is None:  # a goal the nominal model predicts: reachable?
        check_goal(s, nominal, controller, goal)
    return RunSetup(
        scenario=s,
        physics=physics,
        sensors=sensors,
        nominal=nominal,
        estimators=estimators,
        order=order,
        controller=controller,
        goal_pose=goal,
        events=events,
        monitor=monitor,
        true_start=true_start,
        homing_offset=offset,
        drum_zero_errors=drum_zero_errors(s, physics.n_cables),
        shown_view=shown_view,
    )


def _monitor(s: Scenario, physics):
    """The robot's monitor, hooked into the physics (after the events), or ``None``.

    The tension sensors' range top is the robot's (robot.toml), unless the scenario sets one.
    """
    from cdpr_twin.sim import Monitor, robot_limits
    from cdpr_twin.sim.model import robot_sensing

    if not s.monitor.enabled:
        return None
    sensor_max, robot = s.realism.tension.range_max, robot_sensing(physics.model)
    if math.isnan(sensor_max):
        sensor_max = math.inf if robot is None else robot.tension_range[1]
    limits = robot_limits(physics, sensor_max, s.model.control_period)
    monitor = Monitor(physics, limits)
    physics.add_hook(monitor)
    return monitor


def _scene(setup: RunSetup) -> SceneInfo:
    p, g = setup.physics, setup.physics.geometry
    tag = setup.nominal.T_base_tag is not None and p.has_tag
    return SceneInfo(
        a_base=g.a_base,
        b_platform=g.b_platform,
        platform_half_size=p.platform_half_size,
        T_platform_cam=g.T_platform_cam,
        intrinsics=setup.nominal.intrinsics,
        T_base_tag=p.T_base_tag if tag else None,
        tag_size=setup.nominal.tag_size if tag else 0.0,
        frame_min=g.frame_min,
        frame_max=g.frame_max,
        model_file=setup.scenario.model.file,
    )


def _recorders(setup: RunSetup, out_dir, record_rrd: bool, spawn: bool, connect) -> Recorders:
    s = setup.scenario
    names, m = s.estimators.names, setup.physics.n_cables
    rid = f"{s.name}-{s.seed}"
    return Recorders(out_dir, _scene(setup), names, m, rid, record_rrd, spawn, setup.cov, connect)


def run(
    scenario: Scenario,
    out_dir: Path | None = None,
    progress: Callable[[float, float], None] | None = None,
    spawn: bool = False,
    record_rrd: bool = True,
    connect: str | None = None,
) -> RunResult:
    """Run a scenario headless and write its outputs.

    Args:
        scenario: a validated scenario.
        out_dir: output directory (created); ``None`` writes nothing.
        progress: called after each tick with (fraction done, simulated time).
        spawn: also stream to a live Rerun viewer.
        record_rrd: write ``recording.rrd`` (with ``out_dir``).
        connect: also stream to the Rerun gRPC server at this URL (``rerun+http://…/proxy``).

    Returns:
        The :class:`RunResult`. On Ctrl-C (SIGTERM:
        :class:`~cdpr_twin.files.transaction.Terminated`) the
        outputs so far are saved, ``"status": "interrupted"`` (``"terminated"``); raised again.

    Raises:
        ScenarioError: the scenario cannot run (before any output is written).
        OutputDirError: ``out_dir`` cannot be used, another run or command owns it (untouched).
        OutputError: an output could not be written (all left ``*.partial``, no summary).
        RuntimeError: a plugin called ``sys.exit()`` (the run is recorded as failed).
    """
    setup = prepare(scenario)
    owner, metrics, recorders = _claim(setup, out_dir, record_rrd, spawn, connect)
    tally, status, commit, started = Tally(), "running", True, time.perf_counter()
    try:
        status = _loop(setup, (metrics, recorders, tally), progress)
    except OutputError:  # nothing is renamed: what was written stays *.partial
        status, commit = "failed: output", False
        raise
    except BaseException as exc:  # diverged, impossible, a plugin's sys.exit(): failed
        if (stop := interruption(exc)) is not None:  # Ctrl-C, or SIGTERM as the command raises it
            status = Status.TERMINATED if isinstance(stop, Terminated) else Status.INTERRUPTED
            raise stop from None  # (also when it landed in compiled code)
        status = f"failed: {type(exc).__name__}: {exc}"
        if isinstance(exc, SystemExit):  # its code is not the command's exit code
            raise RuntimeError(f"sys.exit({exc.code!r}) called during the run") from None
        raise
    finally:
        wall = time.perf_counter() - started
        with shielded():  # a second Ctrl-C or SIGTERM cannot leave the outputs half-saved
            try:
                summary = summarize(setup, metrics, status, tally)
                recorders.close(summary, commit)
            finally:
                setup.close()
                owner.release()
    return RunResult(summary, wall, out_dir)


def _claim(setup: RunSetup, out_dir, record_rrd, spawn, connect) -> tuple:
    """The claimed output directory, the metrics and the recorders (nothing held on failure)."""
    s = setup.scenario
    # another command's directory is refused (else emptied or mixed), and so is a file of an
    # output's name that no run of ours wrote, or that is this run's own input
    inputs = (s.source, s.model.file, s.model.nominal)
    owner = OutputDir(out_dir, foreign=others("run"), inputs=inputs)
    try:
        owner.claim()  # the lock, then an earlier run's files removed
        # a run's setup always has a controller (only calibration's acquisition has none)
        assert setup.controller is not None
        checkpoints = setup.controller.checkpoints(s.duration)
        metrics = RunMetrics(s.estimators.names, checkpoints, s.model.control_period)
        return owner, metrics, _recorders(setup, out_dir, record_rrd, spawn, connect)
    except BaseException as exc:  # nothing recorded: no header-only *.partial but a failed write's
        setup.close()
        owner.release() if isinstance(exc, OutputError) else owner.abandon()
        raise


def _loop(setup: RunSetup, sinks: tuple, progress) -> str:
    """Drive the run's episode until it ends; returns the run's status."""
    s = setup.scenario
    n_ticks = round(s.duration / s.model.control_period)
    episode = Episode(setup, sinks, true_tag_view=tag_view(setup))
    tick = episode.reset()
    if tick.stop:  # a fault already at the start
        return tick.stop
    # every tick's record is shielded: one handler for the whole loop, not two swaps a tick
    with held_here():
        for k in range(n_ticks):
            tick = episode.step()
            if progress is not None:
                progress((k + 1) / n_ticks, tick.time)
            if tick.stop:  # stopped at the tick the fault happened in
                return tick.stop
            # a run's ticks always carry its controller's command
            assert tick.command is not None and setup.controller is not None
            if tick.command.done:
                return tick.command.status
    assert setup.controller is not None
    return setup.controller.timeout_status
