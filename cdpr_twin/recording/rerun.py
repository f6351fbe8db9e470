"""The Rerun recording ``recording.rrd`` of a run (:class:`RerunRecorder`).

:class:`cdpr_twin.recording.sinks.Recorders` sends a tick to ``timeseries.csv`` (whose schema
:mod:`cdpr_twin.recording.timeseries` owns) and to this recording.

Written as ``recording.rrd.partial``, renamed when complete (:mod:`cdpr_twin.files.transaction`).

Rerun entity paths (they follow the frame tree, docs/concepts/frames.md):

| path | content |
|---|---|
| ``world/frame`` | the 1.2 m frame's edges (static) |
| ``world/exit_points`` | the true exit points A_i (static) |
| ``world/tag`` | the true tag pose and plate (static) |
| ``world/cables`` | cable segments A_i → B_i, coloured by tension, slack ones grey and thin |
| ``world/platform`` | ground-truth platform pose and box |
| ``world/platform/cam`` | the camera mounting and pinhole (OpenCV convention) |
| ``world/platform/cam/image`` | the rendered frame (JPEG) |
| ``world/platform/cam/image/tag`` | detected tag outline (image pixels) |
| ``world/estimates/<name>`` | each estimator's pose, as axes |
| ``world/estimates/<name>/covariance`` | its 3σ position ellipsoid (F_p), when it has one |
| ``world/plan`` | the open-loop plan's current pose, as axes |
| ``deviation/translation_mm`` | ‖t_est − t_true‖ per estimator [mm] (one series each) |
| ``deviation/rotation_deg`` | angle of R_estᵀ R_true per estimator [deg] |
| ``tension`` | measured tensions, one series per cable [N] |
| ``length`` | encoder (rest) lengths, one series per cable [m] |
| ``events`` | scenario events (warning) and the robot's faults (error), as a text log |

The recording carries the viewer's default layout (:func:`default_blueprint`): the 3D scene, the
onboard camera, the deviations and the tensions, each estimator in one colour in both plots.
"""

from __future__ import annotations

import inspect
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_twin.files.transaction import OutputError, Partial, writing
from cdpr_twin.math.se3 import covariance_ellipsoids, pose_distance, quat_xyzw_from_matrix
from cdpr_twin.recording import watchdog
from cdpr_twin.types import CameraIntrinsics, Measurement, PoseEstimate

SLACK_TENSION = 0.5
"""Below this measured tension [N] a cable is drawn as slack."""

_NO_COVARIANCE = np.full((6, 6), np.nan)
"""The covariance of an estimate that gives none (no ellipsoid is drawn)."""

LIVE_FLUSH_TIMEOUT_S = 10.0
"""How long the end of a run waits for a live viewer (``spawn``/``connect``) to take the data [s]:
one that is not listening would otherwise hold the run, its lock and its signals, forever."""


@dataclass(frozen=True, eq=False)
class SceneInfo:
    """The static scene, as the recorder draws it (true robot geometry).

    Attributes:
        a_base: (m, 3) exit points [m].
        b_platform: (m, 3) anchor points [m].
        platform_half_size: (3,) platform box half-sizes [m].
        T_platform_cam: (4, 4) camera mounting (OpenCV frame).
        intrinsics: camera intrinsics, or ``None`` without camera.
        T_base_tag: (4, 4) tag pose (pupil frame), or ``None``.
        tag_size: tag edge [m].
        frame_min: (3,) frame lower corner [m].
        frame_max: (3,) frame upper corner [m].
        model_file: the robot's MJCF scene (its name titles the 3D view), if known.
    """

    a_base: np.ndarray
    b_platform: np.ndarray
    platform_half_size: np.ndarray
    T_platform_cam: np.ndarray
    intrinsics: CameraIntrinsics | None
    T_base_tag: np.ndarray | None
    tag_size: float
    frame_min: np.ndarray
    frame_max: np.ndarray
    model_file: Path | None = None


class RerunRecorder:
    """Logs the run to a ``.rrd`` file (and optionally live: a spawned viewer or a server).

    ``spawn`` starts a Rerun viewer and streams to it; ``connect`` streams to a Rerun gRPC server
    already listening at that URL (``rerun+http://host:port/proxy``). A live stream that cannot
    be delivered (viewer closed, server gone) does not fail the run: the file is still written.
    """

    def __init__(
        self,
        path: Path,
        scene: SceneInfo,
        estimators: tuple[str, ...],
        application_id: str,
        recording_id: str,
        spawn: bool = False,
        jpeg_quality: int = 80,
        flush_every: int | None = None,
        covariance: tuple[str, ...] = (),
        connect: str | None = None,
    ) -> None:
        import rerun as rr

        self.covariance = tuple(covariance)
        self._ended: bool | None = None  # what disconnect returned, once it has
        self.rr = rr
        self.path = path
        self.scene, self.estimators, self.jpeg_quality = scene, estimators, jpeg_quality
        # column-wise sending costs ~0.5 ms per entity and call (~6 ms a flush, 14 entities):
        # a file run batches 500 ticks (20 s at 25 Hz: ~12 µs a tick, under 2 MB held), a live
        # viewer's 10 (0.4 s)
        live = spawn or connect is not None
        self.flush_every = flush_every or (10 if live else 500)
        self._buf = self._new_buffer()
        # created here afresh (never through a link); Rerun, which opens files only by name,
        # is given the name of this very file (``/proc/self/fd/N``), not ``<path>.partial``
        self._out = Partial(path)
        self._partial, self._sink = self._out.partial, self._out.name_of_fd()
        try:
            self._start(application_id, recording_id, spawn, connect)
        except BaseException:
            self._out.close()
            raise

    def _start(self, application_id: str, recording_id: str, spawn: bool, connect) -> None:
        """Open the recording stream and its sinks: the file, and a live viewer if asked."""
        rr, live = self.rr, spawn or connect is not None
        self.rec = rr.RecordingStream(
            application_id, recording_id=recording_id, send_properties=False
        )
        blueprint = default_blueprint(robot_label(self.scene.model_file))
        self.spawned = False  # streaming live (a spawned viewer or a server at ``connect``)
        if live:
            try:
                if spawn:
                    self.rec.spawn(connect=False)
                self.rec.set_sinks(
                    rr.FileSink(self._sink),
                    rr.GrpcSink(connect),  # None: the spawned viewer's default address
                    default_blueprint=blueprint,
                )
                self.spawned = True
            except Exception:  # no viewer binary or no display: keep the file only
                self.spawned = False
        # a file sink that writes a footer ends the file with "RRF2FOOT" + version: its
        # absence after disconnect is a failed write (Rerun reports those only in its log)
        self._footer = "write_footer" in inspect.signature(self.rec.save).parameters
        if not self.spawned:
            try:
                self.rec.save(self._sink, default_blueprint=blueprint)
            except RuntimeError as exc:  # Rerun's words for an OSError
                raise OutputError(self._partial, str(exc)) from None
        self._log_static()

    def _log_static(self) -> None:
        rr, rec, s = self.rr, self.rec, self.scene
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lo, hi = s.frame_min, s.frame_max
        corners = np.array(
            [[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
        )
        # corner i is at hi in x, y, z where bit 0, 1, 2 of i is set: an edge joins two corners
        # that differ in one bit (the four edges along x, then along y, then along z)
        edges = [(i, i ^ bit) for bit in (1, 2, 4) for i in range(8) if not i & bit]
        frame = rr.LineStrips3D([corners[list(e)] for e in edges], colors=[150, 150, 160])
        rec.log("world/frame", frame, static=True)
        exits = rr.Points3D(s.a_base, radii=0.008, colors=[230, 140, 30])
        rec.log("world/exit_points", exits, static=True)
        if s.T_base_tag is not None:
            rec.log(
                "world/tag",
                rr.Transform3D(translation=s.T_base_tag[:3, 3], mat3x3=s.T_base_tag[:3, :3]),
                static=True,
            )
            rec.log(
                "world/tag/plate",
                rr.Boxes3D(
                    half_sizes=[s.tag_size / 2, s.tag_size / 2, 0.0005], colors=[20, 20, 20]
                ),
                static=True,
            )
        self._log_platform()
        for name in self.estimators:
            rec.log(f"world/estimates/{name}", rr.TransformAxes3D(0.06), static=True)
        rec.log("world/plan", rr.TransformAxes3D(0.04), static=True)
        cables = [f"cable {i + 1}" for i in range(len(s.a_base))]
        rec.log("tension", rr.SeriesLines(names=cables), static=True)
        rec.log("length", rr.SeriesLines(names=cables), static=True)
        lines = rr.SeriesLines(
            names=list(self.estimators), colors=series_colors(len(self.estimators))
        )
        for kind in ("translation_mm", "rotation_deg"):
            rec.log(f"deviation/{kind}", lines, static=True)

    def _log_platform(self) -> None:
        """The platform box, and the camera's mounting and pinhole when there is a camera."""
        rr, rec, s = self.rr, self.rec, self.scene
        rec.log(
            "world/platform/box",
            rr.Boxes3D(half_sizes=s.platform_half_size, colors=[70, 90, 130]),
            static=True,
        )
        K = s.intrinsics
        if K is None:
            return
        T = s.T_platform_cam
        rec.log(
            "world/platform/cam",
            rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
            static=True,
        )
        rec.log(
            "world/platform/cam",
            rr.Pinhole(
                image_from_camera=K.K,
                resolution=[K.width, K.height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.05,
            ),
            static=True,
        )

    def tick(
        self,
        m: Measurement,
        T_true: np.ndarray,
        estimates: dict[str, PoseEstimate],
        plan: np.ndarray | None,
    ) -> None:
        """Buffer one tick (sent column-wise every ``flush_every`` ticks); log the image now."""
        b = self._buf
        b["time"].append(m.time)
        # the truth, then each estimator: one array and one quaternion conversion at the flush
        poses = [T_true]
        for name in self.estimators:
            poses.append(estimates[name].T_base_platform)
        b["poses"].append(poses)
        b["tension"].append(m.tensions)
        b["length"].append(m.cable_lengths)
        if self.covariance:
            covariances = []
            for name in self.covariance:
                P = estimates[name].covariance
                covariances.append(_NO_COVARIANCE if P is None else P)
            b["covariance"].append(covariances)
        if plan is not None:
            b["plan_time"].append(m.time)
            b["plan"].append(plan)
        if m.image is not None:
            rr, rec = self.rr, self.rec
            rec.set_time("sim_time", duration=m.time)
            rec.log(
                "world/platform/cam/image",
                rr.Image(m.image).compress(jpeg_quality=self.jpeg_quality),
            )
            if m.tag is not None:
                c = np.vstack([m.tag.corners, m.tag.corners[:1]])
                rec.log("world/platform/cam/image/tag", rr.LineStrips2D([c], colors=[0, 255, 0]))
            else:
                rec.log("world/platform/cam/image/tag", rr.Clear(recursive=False))
        if len(b["time"]) >= self.flush_every:
            self._flush()

    def mark(self, time: float, marks: tuple[str, ...]) -> None:
        """Log what happened at ``time`` [s] (events, faults) to ``events``, a text log.

        Faults are logged at level ``ERROR``, scenario events at ``WARN``, so the viewer's
        text-log view shows them in colour on the run's timeline.
        """
        rr, rec = self.rr, self.rec
        rec.set_time("sim_time", duration=time)
        for text in marks:
            level = rr.TextLogLevel.ERROR if text.startswith("fault") else rr.TextLogLevel.WARN
            rec.log("events", rr.TextLog(text, level=level))

    def _new_buffer(self) -> dict[str, list]:
        keys = ("time", "poses", "tension", "length", "covariance", "plan_time", "plan")
        return {k: [] for k in keys}

    def _flush(self) -> None:
        """Send the buffered ticks column-wise (one call per entity)."""
        rr, rec, b = self.rr, self.rec, self._buf
        n = len(b["time"])
        if n == 0:
            return
        index = [rr.TimeColumn("sim_time", duration=np.array(b["time"]))]
        poses = np.array(b["poses"])  # (n, 1 + estimators, 4, 4): the truth, then each estimator
        quaternions = quat_xyzw_from_matrix(poses[..., :3, :3])
        paths = ["world/platform", *(f"world/estimates/{name}" for name in self.estimators)]
        for j, path in enumerate(paths):
            self._send_transforms(path, index, poses[:, j, :3, 3], quaternions[:, j])
        if self.covariance:
            covariances = np.array(b["covariance"])  # (n, covariance, 6, 6)
            for j, name in enumerate(self.covariance):
                half, quat = covariance_ellipsoids(covariances[:, j, :3, :3])
                rec.send_columns(
                    f"world/estimates/{name}/covariance",
                    indexes=index,
                    columns=rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quat),
                )
        if b["plan"]:
            plan = np.array(b["plan"])
            self._send_transforms(
                "world/plan",
                [rr.TimeColumn("sim_time", duration=np.array(b["plan_time"]))],
                plan[:, :3, 3],
                quat_xyzw_from_matrix(plan[:, :3, :3]),
            )
        tau = np.array(b["tension"])
        self._send_cables(index, poses[:, 0], tau)
        rec.send_columns("tension", indexes=index, columns=rr.Scalars.columns(scalars=tau))
        rec.send_columns(
            "length", indexes=index, columns=rr.Scalars.columns(scalars=np.array(b["length"]))
        )
        dts, drs = pose_distance(poses[:, 1:], poses[:, :1])  # (n, estimators) each
        rec.send_columns(
            "deviation/translation_mm",
            indexes=index,
            columns=rr.Scalars.columns(scalars=dts * 1e3),
        )
        rec.send_columns(
            "deviation/rotation_deg",
            indexes=index,
            columns=rr.Scalars.columns(scalars=np.degrees(drs)),
        )
        self._buf = self._new_buffer()

    def _send_transforms(
        self, path: str, index: list, translation: np.ndarray, quaternion: np.ndarray
    ) -> None:
        """Send a pose per index row: (n, 3) translations [m], (n, 4) quaternions (xyzw)."""
        columns = self.rr.Transform3D.columns(translation=translation, quaternion=quaternion)
        self.rec.send_columns(path, indexes=index, columns=columns)

    def _send_cables(self, index: list, platform: np.ndarray, tau: np.ndarray) -> None:
        """Cables A_i → B_i for every buffered tick, coloured by tension, slack ones grey."""
        rr, n, m = self.rr, len(platform), tau.shape[1]
        # B_i in F_b for every buffered tick, (n, m, 3)
        anchors = np.einsum("nij,kj->nki", platform[:, :3, :3], self.scene.b_platform)
        anchors += platform[:, None, :3, 3]
        exits = np.broadcast_to(self.scene.a_base, (n, m, 3))
        strips = np.stack([exits, anchors], axis=2).reshape(n * m, 2, 3)
        taut = (tau > SLACK_TENSION).ravel()
        level = np.clip(tau.ravel() / 30.0, 0.0, 1.0)
        colors = np.where(
            taut[:, None],
            np.column_stack([40 + 215 * level, 200 - 150 * level, 255 - 215 * level]),
            [[120, 120, 120]],
        ).astype(np.uint8)
        self.rec.send_columns(
            "world/cables",
            indexes=index,
            columns=rr.LineStrips3D.columns(
                strips=strips, colors=colors, radii=np.where(taut, 0.003, 0.001)
            ).partition(lengths=[m] * n),
        )

    def finish(self) -> None:
        """Send what is buffered, flush (Rerun's writer thread), ``fsync`` and disconnect.

        Raises:
            OutputError: Rerun could not write the file (its own log says why). With a live
                viewer a failed flush is not an error: the viewer may have been closed.
        """
        self._flush()
        try:  # a live viewer that does not take the data must not hold the run forever
            if self.spawned:
                self.rec.flush(timeout_sec=LIVE_FLUSH_TIMEOUT_S)
            else:  # nor a file writer that died mid-flush (Rerun's flush would wait forever)
                watchdog.flush_while_writing(
                    lambda t: self.rec.flush(timeout_sec=t), Path(self._sink)
                )
        except Exception as exc:
            if not self.spawned:
                self.abort(stalled=isinstance(exc, watchdog.WriterStalledError))
                raise OutputError(self._partial, f"Rerun could not write it: {exc}") from None
            why = f"the live viewer did not take all of the recording (≤ {LIVE_FLUSH_TIMEOUT_S:g}"
            warnings.warn(f"{why} s: {exc}); the file is whole", RuntimeWarning, stacklevel=2)
        ended = self._disconnect(watchdog.ABANDON_S)  # writes the footer (Rerun ≥ 0.23)
        with writing(self._partial), open(self._sink, "rb") as f:
            os.fsync(f.fileno())
            f.seek(max(0, os.fstat(f.fileno()).st_size - 16))
            whole = b"FOOT" in f.read() or (ended and not self._footer)
        if not whole:
            late = "" if ended else f" (its disconnect not done in {watchdog.ABANDON_S:g} s)"
            raise OutputError(self._partial, f"incomplete: Rerun could not write its end{late}")

    def commit(self) -> None:
        """Give the finished file its final name."""
        self._out.commit()

    def abort(self, stalled: bool = False) -> None:
        """Stop recording: what was written stays ``<path>.partial`` (``stalled``: writer dead)."""
        self._disconnect(0.0 if stalled else watchdog.ABANDON_S)
        self._out.close()

    def _disconnect(self, wait: float) -> bool:
        """Rerun's disconnect, once, waited for ≤ ``wait`` [s] (a dead writer blocks it forever)."""
        if self._ended is None:
            late = self.rr.unregister_shutdown
            self._ended = watchdog.call_with_deadline(self.rec.disconnect, wait, late)
        return self._ended

    def close(self) -> None:
        """Finish and give the file its final name."""
        self.finish()
        self.commit()


# ------------------------------------------------------------- the viewer's default layout
PALETTE = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)
"""Series colours (RGB), one per estimator in recording order (matplotlib's tab10): each
estimator keeps its colour in both deviation plots, so one legend reads both."""


def robot_label(model_file: Path | None) -> str:
    """A robot's name from its MJCF scene: ``models/acrobot/scene.xml`` → ``ACROBOT``."""
    if model_file is None:
        return "robot"
    return (model_file.parent.name if model_file.stem == "scene" else model_file.stem).upper()


def series_colors(n: int) -> list[tuple[int, int, int]]:
    """``n`` series colours (RGB 0-255), distinct up to 10 and cycling after."""
    return [PALETTE[i % len(PALETTE)] for i in range(n)]


def default_blueprint(robot: str = "robot"):
    """The default layout: 3D scene, camera image, deviations and tensions over time.

    Args:
        robot: the 3D view's title (the robot's name).
    """
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name=robot),
            rrb.Vertical(
                rrb.Spatial2DView(origin="world/platform/cam", name="onboard camera"),
                rrb.TimeSeriesView(
                    origin="deviation/translation_mm", name="estimate − truth: position [mm]"
                ),
                rrb.TimeSeriesView(
                    origin="deviation/rotation_deg", name="estimate − truth: rotation [°]"
                ),
                rrb.TimeSeriesView(origin="tension", name="tensions [N]"),
                row_shares=[3, 2, 2, 2],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
