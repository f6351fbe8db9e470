"""Where each tick goes: ``timeseries.csv`` and ``recording.rrd``; ``summary.json`` last.

The files are closed as one transaction (:meth:`Recorders.close`; the directory's promises:
:mod:`cdpr_twin.files.transaction`).
"""

from __future__ import annotations

from pathlib import Path

from cdpr_twin.files.transaction import fsync_dir, write_json_partial, writing
from cdpr_twin.recording.rerun import RerunRecorder, SceneInfo
from cdpr_twin.recording.timeseries import TimeseriesWriter
from cdpr_twin.types import TickRecord


class Recorders:
    """Where each tick goes: ``timeseries.csv`` and, optionally, ``recording.rrd``.

    Args:
        out_dir: the run's output directory (created), or ``None`` to record nothing.
        scene: the static scene (for Rerun).
        names: the estimators, in recording order.
        n_cables: the robot's cable count.
        recording_id: the Rerun recording id.
        rrd: write ``recording.rrd``.
        spawn: also stream to a live Rerun viewer.
        covariance: the estimators whose estimates carry a covariance (recorded too).
        connect: also stream to the Rerun gRPC server at this URL.
    """

    def __init__(
        self,
        out_dir: Path | None,
        scene: SceneInfo,
        names: tuple[str, ...],
        n_cables: int,
        recording_id: str,
        rrd: bool = True,
        spawn: bool = False,
        covariance: tuple[str, ...] = (),
        connect: str | None = None,
    ) -> None:
        self.out_dir = out_dir
        self.csv: TimeseriesWriter | None = None
        self.rrd: RerunRecorder | None = None
        if out_dir is None:
            return
        with writing(out_dir):
            out_dir.mkdir(parents=True, exist_ok=True)
        self.csv = TimeseriesWriter(
            out_dir / "timeseries.csv", names, n_cables, covariance=covariance
        )
        if rrd:
            try:
                self.rrd = RerunRecorder(
                    out_dir / "recording.rrd",
                    scene,
                    names,
                    "cdpr-twin",
                    recording_id,
                    spawn,
                    covariance=covariance,
                    connect=connect,
                )
            except BaseException:
                self.csv.abort()
                raise

    def add(self, tick: TickRecord) -> None:
        """Record one control tick (its marks: what happened in it, events and faults)."""
        m, marks = tick.measurement, tick.marks
        if self.csv is not None:
            self.csv.tick(
                tick.time, tick.T_base_platform, tick.estimates, m, tick.command, tick.plan, marks
            )
        if self.rrd is not None:
            self.rrd.tick(m, tick.T_base_platform, tick.estimates, tick.plan)
            if marks:
                self.rrd.mark(m.time, marks)

    def close(self, summary: dict, commit: bool = True) -> None:
        """Complete every file, then give them final names, ``summary.json`` last.

        Every file is finished (flushed, ``fsync``'ed) before any is renamed, so a failed write
        renames nothing.

        Args:
            summary: the content of ``summary.json`` (``ticks_recorded`` is added).
            commit: ``False`` after an output error: close, leave every file ``*.partial``.

        Raises:
            OutputError: a file could not be written (every file is left ``*.partial``).
        """
        writers = [w for w in (self.csv, self.rrd) if w is not None]
        try:
            if not commit or self.out_dir is None:
                return
            for w in writers:
                w.finish()
            if self.csv is not None:
                summary["ticks_recorded"] = self.csv.rows
            marker = write_json_partial(self.out_dir / "summary.json", summary)
        finally:
            for w in writers:
                w.abort()  # no-op once finished
        for w in writers:
            w.commit()
        fsync_dir(self.out_dir)  # the files' names before the commit marker's
        marker.commit()
        fsync_dir(self.out_dir)
