"""Record the excitation in the twin: drive, settle, read encoders, tensions and the tag.

The robot is homed at the scenario's start pose exactly as a run homes it (the true platform
moved by the run's homing offset, the encoders zeroed as if it stood at the nominal start),
then driven open loop through the excitation poses: straight quintic lines (eq. 26-29) whose
cable rates are the *nominal* model's length changes from tick to tick, so the true robot goes
wherever its true geometry and physics put it. At each pose it rests, waits out the camera's
latency, and averages ``frames`` readings; the first readings are taken where it was homed,
before it moves and untightened (the one pose the robot's software knows, within the
homing's repeatability). The camera is read only where the nominal model
puts the whole tag within :data:`VIEW_MARGIN` of the image and not edge-on (elsewhere nothing
could be detected, and a frame costs more than the physics); at the other poses the readings
are taken without waiting out the camera's latency (the robot is at rest either way). What the
solver gets is :class:`Observations` only; the truth (true poses and geometry) is kept apart in
:class:`Truth`, for the report's check.

The tour is recorded in :data:`SEGMENTS` consecutive segments, each from the same homing (the
twin's equivalent of homing the robot again: at rest poses the path between them leaves no
trace but the tightening's length corrections, which a segment starts without), so that
segments can run side by side on several cores. Their number is fixed and each has its own
sensor-noise seed, derived from the run seed: the readings do not depend on how many workers
recorded them.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace

import numpy as np

from cdpr_twin.calibrate import drive
from cdpr_twin.calibrate.excitation import tag_in_view
from cdpr_twin.calibrate.problem import Detector, Observations
from cdpr_twin.campaign.executor import abandon, exit_with
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import so3_exp, so3_log, transform
from cdpr_twin.run.episode import Episode, start
from cdpr_twin.run.homing_and_teaching import homing
from cdpr_twin.run.runner import RunSetup
from cdpr_twin.scenario.loading import Scenario, ScenarioError

SETTLE = 0.6
"""Rest before reading at each pose [s] (the platform's swing decays in ≈ 0.3 s)."""

SWING = 0.3
"""Rest after a move before tightening [s]: the swing has decayed (≈ 0.3 s), and the
tightening's internal-force steps do not move the platform."""

SEGMENTS = 4
"""The tour is recorded in this many segments (fewer when there are fewer poses)."""

VIEW_MARGIN = -60.0
"""The camera is read where the nominal model puts the whole tag at least this far inside the
image [px]; negative: up to 60 px outside it, a margin for the true robot's different pose."""


@dataclass(frozen=True, eq=False)
class Truth:
    """The twin's ground truth during the recording (never shown to the solver).

    Attributes:
        T_base_platform: (K, 4, 4) true poses at the readings.
        geometry: the simulated robot's true :class:`~cdpr_twin.math.geometry.CdprGeometry`.
        T_base_tag: (4, 4) the true tag pose.
        drum_scale: (m,) true drum radius / the radius its drive and encoder were set to − 1.
        intrinsics_error: (8,) the detector's intrinsics minus the true ones (fx, fy, cx, cy
            [px], k1, k2, p1, p2).
        tension_bias: (m,) each tension sensor's offset [N].
        tension_gain: (m,) each tension sensor's relative gain error.
    """

    T_base_platform: np.ndarray
    geometry: CdprGeometry
    T_base_tag: np.ndarray
    drum_scale: np.ndarray
    intrinsics_error: np.ndarray
    tension_bias: np.ndarray
    tension_gain: np.ndarray


@dataclass(frozen=True, eq=False)
class Recording:
    """An excitation's readings, the nominal robot they refer to, and the truth beside them.

    Attributes:
        obs: what the solver sees.
        nominal: the robot's software model (:class:`cdpr_twin.sim.NominalRobot`).
        detector: what the software assumes of its tag detector (its calibrated intrinsics).
        truth: ground truth, for the report only.
        simulated_time: simulated seconds [s].
        wall_time: wall-clock seconds of the recording [s].
        drum_radii: (m,) the radii the drives and encoders were set to [m] (the nominal
            description's, or the model's).
        tension_sensors: the tension sensors' specification (not their drawn errors): offset
            std [N], relative gain error std, reading noise std [N].
    """

    obs: Observations
    nominal: object
    detector: Detector
    truth: Truth
    simulated_time: float
    wall_time: float
    drum_radii: np.ndarray
    tension_sensors: tuple[float, float, float]

    def subset(self, keep: np.ndarray) -> Recording:
        """The recording at the poses ``keep`` (a (K,) mask or indices) selects."""
        truth = replace(self.truth, T_base_platform=self.truth.T_base_platform[keep])
        return replace(self, obs=self.obs.subset(keep), truth=truth)


@dataclass(frozen=True, eq=False)
class Reading:
    """The averaged readings at one pose.

    Attributes:
        encoder: (m,) mean encoder lengths [m].
        tensions: (m,) mean tension readings [N].
        taut: (m,) each cable read taut (above 1 N, unclipped) in every reading.
        T_cam_tag: (4, 4) the mean detected tag pose, or ``None`` (not seen).
    """

    encoder: np.ndarray
    tensions: np.ndarray
    taut: np.ndarray
    T_cam_tag: np.ndarray | None


@dataclass(frozen=True, eq=False)
class _Segment:
    """One segment of the tour, as its process recorded it.

    Attributes:
        index: its place in the tour.
        readings: one per pose read.
        true_poses: (4, 4) the true platform pose at each reading.
        simulated_time: simulated seconds [s].
        geometry: the simulated robot's true geometry.
        T_base_tag: (4, 4) the true tag pose.
        drum_scale: (m,) true drum radius / the radius set − 1.
        intrinsics_error: (8,) the detector's intrinsics minus the true ones.
        nominal: the robot's software model.
        detector: what the software assumes of its tag detector.
        drum_radii: (m,) the radii the drives and encoders were set to [m].
        tension_sensors: offset std [N], relative gain error std, reading noise std [N].
        tension_bias: (m,) each tension sensor's drawn offset [N].
        tension_gain: (m,) each tension sensor's drawn relative gain error.
    """

    index: int
    readings: list[Reading]
    true_poses: list[np.ndarray]
    simulated_time: float
    geometry: CdprGeometry
    T_base_tag: np.ndarray
    drum_scale: np.ndarray
    intrinsics_error: np.ndarray
    nominal: object
    detector: Detector
    drum_radii: np.ndarray
    tension_sensors: tuple[float, float, float]
    tension_bias: np.ndarray
    tension_gain: np.ndarray


def _read(
    episode: Episode,
    frames: int,
    wait: int,
    look: bool,
    geometry=None,
    moved_to: np.ndarray | None = None,
) -> Reading:
    """Rest, tighten, then average ``frames`` readings.

    Tightening only after a move (``moved_to``: the pose commanded, in the nominal
    ``geometry``); the camera's readings only if ``look``. Each reading is taken, and then
    the robot rests a control period (the tick's two halves in the order a reading is held).
    """
    physics, period = episode.setup.physics, episode.period
    rest = np.zeros(physics.n_cables)
    if moved_to is not None:
        episode.advance(round(SWING / period) * period, rest)
        drive.tighten_with(
            episode.advance,
            lambda: episode.read(render=False).measurement.tensions,
            physics.timestep,
            geometry,
            moved_to,
        )
    settle = round(SETTLE / period) * period
    episode.advance(settle - period * look, rest)
    if look:  # the camera records the states of its exposures from the tick before its reads
        _exposures(episode.setup.sensors, True)
        episode.advance(period, rest)
    for _ in range(wait if look else 0):
        episode.read()
        episode.advance(period, rest)
    enc, ten, tags, ok = [], [], [], None
    for _ in range(frames):
        m = episode.read(render=look).measurement
        enc.append(m.cable_lengths)
        ten.append(m.tensions)
        clipped = m.tensions_clipped if m.tensions_clipped is not None else False
        good = (m.tensions > 1.0) & ~np.asarray(clipped, bool)
        ok = good if ok is None else ok & good
        if m.tag is not None:
            tags.append(m.tag.T_cam_tag)
        episode.advance(period, rest)
    _exposures(episode.setup.sensors, False)
    # (record() refuses frames < 1: at least one reading set ok)
    assert ok is not None
    return Reading(np.mean(enc, axis=0), np.mean(ten, axis=0), ok, _mean_pose(tags))


def _exposures(sensors, on: bool) -> None:
    """Record the robot's states for the camera's motion blur (``on``) or not.

    Off while the robot moves and tightens, where the camera is not read: a hook less to stop
    the physics at every sub-frame time.
    """
    recorder = sensors.camera.exposure if sensors.camera is not None else None
    if recorder is not None:
        recorder.active = on


def _mean_pose(poses: list[np.ndarray]) -> np.ndarray | None:
    """The mean of poses close together (rotation: mean twist about the first), or None."""
    if not poses:
        return None
    R0 = poses[0][:3, :3]
    w = np.mean([so3_log(R0.T @ T[:3, :3]) for T in poses], axis=0)
    return transform(R0 @ so3_exp(w), np.mean([T[:3, 3] for T in poses], axis=0))


def record(
    s: Scenario,
    poses: list[np.ndarray],
    frames: int = 4,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> Recording:
    """Home the scenario's robot, record it there, drive it through ``poses`` and record each.

    The observations' first row is the homed robot's (``home``; ``T_guess`` the start pose),
    then one per pose of ``poses``.

    Args:
        s: the scenario (robot, truth seed, realism, run seed, start pose, stepping).
        poses: (4, 4) poses to visit, in order.
        frames: readings averaged at each pose.
        workers: processes recording the tour's segments side by side (the readings do not
            depend on it).
        progress: called with (segments recorded, segments) as each segment ends.

    Raises:
        ScenarioError: the scenario's robot cannot be built, has no camera, or its start pose
            cannot be homed at.
        ValueError: ``frames`` < 1.
    """
    if frames < 1:
        raise ValueError(f"frames must be ≥ 1 (readings averaged per pose), got {frames}")
    _refuse_what_it_cannot_use(s)
    started = time.perf_counter()
    n = min(SEGMENTS, len(poses))
    bounds = np.linspace(0, len(poses), n + 1).round().astype(int)
    parts = [poses[bounds[i] : bounds[i + 1]] for i in range(n)]
    tell = progress or (lambda done, total: None)
    if workers > 1 and n > 1:
        segments = _in_processes(parts, min(workers, n), s, frames, tell)
    else:
        segments = []
        for i, part in enumerate(parts):
            segments.append(_segment(i, part, s, frames))
            tell(i + 1, n)
    first = segments[0]  # the robot and its sensors are the same in every segment
    truth = Truth(
        T_base_platform=np.array([T for seg in segments for T in seg.true_poses]),
        geometry=first.geometry,
        T_base_tag=first.T_base_tag,
        drum_scale=first.drum_scale,
        intrinsics_error=first.intrinsics_error,
        tension_bias=first.tension_bias,
        tension_gain=first.tension_gain,
    )
    return Recording(
        obs=_observations([r for seg in segments for r in seg.readings], [s.start_pose, *poses]),
        nominal=first.nominal,
        detector=first.detector,
        truth=truth,
        simulated_time=float(sum(seg.simulated_time for seg in segments)),
        wall_time=time.perf_counter() - started,
        drum_radii=first.drum_radii,
        tension_sensors=first.tension_sensors,
    )


def _in_processes(
    parts: list[list[np.ndarray]],
    workers: int,
    s: Scenario,
    frames: int,
    tell: Callable[[int, int], None] | None = None,
) -> list[_Segment]:
    """:func:`_segment` of each part of the tour in spawned processes, in order.

    The first failure — a segment's error, a worker that died, Ctrl-C or SIGTERM in this
    process — ends the other segments at once: nothing is left running.
    """
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        workers, mp_context=ctx, initializer=_worker_start, initargs=(os.getpid(),)
    ) as pool:
        futures = [pool.submit(_segment, i, part, s, frames) for i, part in enumerate(parts)]
        try:
            for done, f in enumerate(as_completed(futures), 1):
                f.result()  # raises the segment's error (BrokenProcessPool: a worker died)
                if tell is not None:
                    tell(done, len(futures))
        except BaseException:
            abandon(pool)
            raise
        return [f.result() for f in futures]


def _build(s: Scenario):
    """The scenario's simulated robot and its nominal model, as a segment records them.

    Returns:
        The :class:`~cdpr_twin.sim.twin.BuiltRobot`.

    Raises:
        ScenarioError: the robot cannot be built, or has no camera or tag.
    """
    from cdpr_twin.sim import ModelError, build_robot

    try:
        built = build_robot(
            s.model.file,
            s.truth,
            s.model.timestep,
            s.model.align_every,
            s.realism.winch,
            nominal_path=s.model.nominal,
            drive=s.realism.drive,
            cable=s.realism.cable,
            pulley=s.realism.pulley,
        )
    except (ModelError, ValueError) as exc:
        raise ScenarioError(f"{s.source}: model: {exc}") from None
    if built.nominal.T_base_tag is None or built.nominal.intrinsics is None:
        raise ScenarioError(f"{s.source}: model: the robot needs a camera and a tag to calibrate")
    return built


def _start_error(s: Scenario, offset, exc: Exception) -> ScenarioError:
    """The start pose refused: outside the frame, or no tension distribution holds it there.

    The message is ``cdpr-twin run``'s for the same file.
    """
    where = "start.pose" if offset is None else "start.pose (moved by its homing offset)"
    return ScenarioError(f"{s.source}: {where}: {exc}")


def check(s: Scenario) -> None:
    """What would stop the recording, checked in this process before any worker starts.

    The camera is on, no events or payload, the robot builds with a camera and a tag, and its
    true start pose (homing offset applied) is inside the frame and held by some tensions.

    Raises:
        ScenarioError: naming the file and the field at fault, as ``cdpr-twin run`` does.
    """
    _refuse_what_it_cannot_use(s)
    physics = _build(s).physics
    offset, true_start = homing(s)
    try:
        physics.reset(true_start, settle_time=0.0)
    except ValueError as exc:  # outside the frame, or an InfeasibleTensionError
        raise _start_error(s, offset, exc) from None


def _refuse_what_it_cannot_use(s: Scenario) -> None:
    """The camera off, events (its own tour has none), a payload (its balance weighs none)."""
    if not s.sensors.camera:
        raise ScenarioError(f"{s.source}: sensors.camera: calibration needs the camera; set true")
    unused = [
        ("[[events]]", s.events, "drives its own tour"),
        ("model.payload_kg", s.model.payload, "weighs the platform alone"),
    ]
    for field, used, why in unused:
        if used:
            raise ScenarioError(f"{s.source}: {field}: a calibration {why}; remove it from a copy")


def _worker_start(parent: int) -> None:
    """In a worker: Ctrl-C is the parent's to handle; a parent killed without cleanup ends it.

    The parent ends its workers on Ctrl-C or SIGTERM; after SIGKILL or the OOM killer they
    would record on for nobody (and hold the command's output pipe open).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_with(parent)


def _segment(index: int, poses: list[np.ndarray], s: Scenario, frames: int) -> _Segment:
    """Record one segment of the tour (the ``index``-th, through ``poses``) from homing."""
    from cdpr_twin.sim import Sensors
    from cdpr_twin.sim.events import EventSchedule

    built = _build(s)
    physics, nominal = built.physics, built.nominal
    period = s.model.control_period
    seed = (
        s.seed if index == 0 else int(np.random.SeedSequence([s.seed, index]).generate_state(1)[0])
    )
    sensors = Sensors(
        physics,
        nominal,
        s.sensors.tension_noise_std,
        seed,
        camera=True,
        realism=s.realism,
        robot_seed=s.truth.seed,
        period=period,
    )
    offset, true_start = homing(s)
    # no controller: the tour commands every move; no estimator, no event
    setup = RunSetup(
        scenario=s,
        physics=physics,
        sensors=sensors,
        nominal=nominal,
        estimators={},
        order=(),
        controller=None,
        goal_pose=None,
        events=EventSchedule((), physics, sensors),
        true_start=true_start,
        homing_offset=offset,
    )
    episode, g = Episode(setup), nominal.geometry
    try:
        try:
            start(setup)  # the true robot homed at the start pose, as a run homes it
        except ValueError as exc:  # outside the frame, or an InfeasibleTensionError
            raise _start_error(s, offset, exc) from None
        _exposures(sensors, False)
        rows, truth, here = [], [], s.start_pose
        # the first segment first reads where the encoders were homed, as the robot stands
        stops = [(here, False)] * (index == 0) + [(T, True) for T in poses]
        for T, moved in stops:
            if moved:
                drive.move(episode, g, here, T, period)
            look = tag_in_view(
                g, nominal.T_base_tag, nominal.intrinsics, nominal.tag_size, T, VIEW_MARGIN
            )
            wait = s.realism.camera.latency_ticks
            moved_to = T if moved else None
            rows.append(_read(episode, frames, wait, look, g, moved_to))
            truth.append(np.array(physics.T_base_platform))
            here = T
        detector, intrinsics_error = _detector(sensors.camera, nominal.tag_size, s.realism)
        t = sensors.realism.tension
        tension_sensors = (t.bias_std, t.gain_error_std, sensors.tension.noise_std)
        bias, gain = sensors.tension.bias.copy(), sensors.tension.gain_error.copy()
    finally:
        setup.close()
    return _Segment(
        index=index,
        readings=rows,
        true_poses=truth,
        simulated_time=float(physics.time),
        geometry=physics.geometry,
        T_base_tag=np.array(physics.T_base_tag),
        # against what it reads
        drum_scale=physics.drum_radius_true / physics.drum_radius_set - 1.0,
        intrinsics_error=intrinsics_error,
        nominal=nominal,
        detector=detector,
        drum_radii=physics.drum_radius_set.copy(),
        tension_sensors=tension_sensors,
        tension_bias=bias,
        tension_gain=gain,
    )


def _detector(camera, tag_size: float, realism) -> tuple[Detector, np.ndarray]:
    """What the robot's software knows of its tag detector (its calibrated intrinsics).

    Also, for the report only, their error: (8,) calibrated − true fx, fy, cx, cy [px], k1, k2,
    p1, p2.
    """
    cal, true = camera.calibrated, camera.true_intrinsics
    lens = camera.calibrated_distortion or (0.0, 0.0, 0.0, 0.0)
    error = np.array(
        [cal.fx - true.fx, cal.fy - true.fy, cal.cx - true.cx, cal.cy - true.cy]
        + [a - b for a, b in zip(lens, realism.camera.distortion, strict=True)]
    )
    return Detector(tag_size, cal.fx, tuple(lens)), error


def _observations(rows: list[Reading], poses: list[np.ndarray]) -> Observations:
    """The rows read at ``poses``: the first where the encoders were homed, then the tour's."""
    seen = np.array([r.T_cam_tag is not None for r in rows])
    return Observations(
        encoder=np.array([r.encoder for r in rows]),
        tensions=np.array([r.tensions for r in rows]),
        taut=np.array([r.taut for r in rows]),
        T_cam_tag=np.array([np.eye(4) if r.T_cam_tag is None else r.T_cam_tag for r in rows]),
        seen=seen,
        T_guess=np.array(poses),
        home=np.arange(len(rows)) == 0,
    )
