"""The run file ``timeseries.csv``: its schema, its writer and its reader, in one place.

One row per control tick, columns in this order (:func:`header`):

| columns | content |
|---|---|
| ``t`` | time [s] |
| ``true_{x,y,z,qw,qx,qy,qz}`` | ground-truth platform pose T_base_platform [m, unit quaternion] |
| ``<name>_{x,…,qz}``, ``<name>_valid`` | each estimator's pose, and 1 if this tick updated it |
| ``<name>_cov_<a>_<b>`` | covariance of δ (F_p) of an estimator that reports one (``fused``) |
| ``tension_1 … tension_m`` | measured tensions [N] |
| ``length_1 … length_m`` | encoder (unstretched) cable lengths [m] |
| ``rate_1 … rate_m`` | commanded winch rates [m/s] |
| ``plan_{x,…,qz}`` | the open-loop plan's pose (empty cells when there is none) |
| ``tag_{x,…,qz}`` | the detected tag pose T_cam_tag (empty cells when not detected) |
| ``status`` | the controller's :class:`~cdpr_twin.types.Status` (``start`` on the first row) |
| ``event`` | the tick's scenario events and robot faults, ``; ``-separated (mostly empty) |

Covariance columns (21: the upper triangle, a ≤ b in x, y, z, rx, ry, rz; [m², m·rad, rad²])
follow their estimator's ``_valid`` column. Floats are written with ``%.17g``, so every value
reads back exactly. The file is written as ``timeseries.csv.partial`` and renamed when
complete: a file under its final name is whole.
"""

from __future__ import annotations

import contextlib
import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_twin.files.transaction import Partial, writing
from cdpr_twin.math.se3 import matrix_from_quat_wxyz, pose_distance, quat_wxyz_from_matrix
from cdpr_twin.types import Command, Measurement, PoseEstimate, Status

POSE_FIELDS = ("x", "y", "z", "qw", "qx", "qy", "qz")
"""Suffixes of a pose's seven columns: position [m], then the unit quaternion (w first)."""
VALID_SUFFIX = "_valid"
"""Suffix of an estimator's validity column (its name comes before it)."""
CABLE_PREFIXES = ("tension", "length", "rate")
"""Per-cable column groups, in file order: ``<prefix>_1 … <prefix>_m``."""
STATUS_COLUMN = "status"
"""The controller's status (text)."""
EVENT_COLUMN = "event"
"""The last column: events and faults of the tick (text, usually empty)."""
COV_AXES = ("x", "y", "z", "rx", "ry", "rz")
"""Axes of a pose covariance's columns: δ = [v, ω] in F_p."""
COV_INDEX = tuple((i, j) for i in range(6) for j in range(i, 6))
"""The (row, column) of each covariance column, upper triangle row by row (21)."""
_COV_ROWS, _COV_COLS = np.array(COV_INDEX).T
_NO_COVARIANCE = np.full((6, 6), np.nan)
"""The covariance cells of an estimate that gives none: NaN."""
_EYE = np.eye(4)
"""What stands for an absent plan or tag until its cells are left empty."""


def covariance_columns(prefix: str) -> list[str]:
    """The 21 covariance columns ``<prefix>_cov_<a>_<b>`` of an estimator, a ≤ b."""
    return [f"{prefix}_cov_{COV_AXES[i]}_{COV_AXES[j]}" for i, j in COV_INDEX]


def pose_columns(prefix: str) -> list[str]:
    """The seven column names of the pose ``prefix`` (``true``, an estimator, ``plan``, ``tag``)."""
    return [f"{prefix}_{k}" for k in POSE_FIELDS]


def cable_columns(prefix: str, n_cables: int) -> list[str]:
    """``<prefix>_1 … <prefix>_m`` (cables are numbered from 1 in the file)."""
    return [f"{prefix}_{i + 1}" for i in range(n_cables)]


def header(estimators: Sequence[str], n_cables: int, covariance: Sequence[str] = ()) -> list[str]:
    """Every column name of a run with these estimators (in this order) and cables.

    Args:
        estimators: estimator names, in column order.
        n_cables: cable count m.
        covariance: the estimators that report a covariance (their columns follow ``_valid``).
    """
    names = ["t", *pose_columns("true")]
    for name in estimators:
        names += [*pose_columns(name), f"{name}{VALID_SUFFIX}"]
        if name in covariance:
            names += covariance_columns(name)
    for prefix in CABLE_PREFIXES:
        names += cable_columns(prefix, n_cables)
    return [*names, *pose_columns("plan"), *pose_columns("tag"), STATUS_COLUMN, EVENT_COLUMN]


class TimeseriesWriter:
    """Writes ``timeseries.csv``, one row per :meth:`tick`.

    Rows are buffered and written (and flushed) every ``flush_every`` ticks and at
    :meth:`close`, with quaternions converted for the whole batch at once. Until :meth:`close`
    (or :meth:`finish` then :meth:`commit`) the file is ``<path>.partial``; an ``OSError`` is
    raised as :class:`~cdpr_twin.files.transaction.OutputError` naming that file.

    Attributes:
        path: the final file name.
        estimators: estimator names, in column order.
        n_cables: number of cables m.
        flush_every: ticks buffered between writes.
        rows: rows written so far.
    """

    def __init__(
        self,
        path: Path,
        estimators: tuple[str, ...],
        n_cables: int,
        flush_every: int = 25,
        covariance: tuple[str, ...] = (),
    ) -> None:
        self.path = Path(path)
        self._out = Partial(self.path)  # created afresh, never through a link
        self._partial = self._out.partial
        self.estimators = tuple(estimators)
        self.covariance = tuple(n for n in self.estimators if n in covariance)
        self.n_cables = n_cables
        self.flush_every = flush_every
        with writing(self._partial):
            self._file = self._out.file("w", newline="", encoding="utf-8")
            columns = header(self.estimators, n_cables, self.covariance)
            self._file.write(",".join(columns) + "\n")
        self._plan_at = columns.index(pose_columns("plan")[0])
        self._rows: list[tuple] = []
        self._formats: dict[tuple[bool, bool], str] = {}
        self.rows = 0

    def tick(
        self,
        time: float,
        T_true: np.ndarray,
        estimates: dict[str, PoseEstimate],
        measurement: Measurement,
        command: Command | None,
        plan: np.ndarray | None,
        marks: Sequence[str] = (),
    ) -> None:
        """Buffer one row.

        Args:
            time: time of the row [s].
            T_true: (4, 4) ground-truth platform pose.
            estimates: every estimator's estimate, by name (``self.estimators`` at least).
            measurement: the sensors' reading (tensions, lengths, rates, tag).
            command: the command that led here, or ``None`` on the start row.
            plan: (4, 4) planned pose, or ``None``.
            marks: what happened during the tick (events, faults), in words.
        """
        m = measurement
        tag = None if m.tag is None else m.tag.T_cam_tag
        # the arrays as they are, converted to numbers a batch at a time (:meth:`flush`); an
        # absent plan or tag stands as the identity, its cells left empty
        poses = [T_true]
        valid = []
        for n in self.estimators:
            e = estimates[n]
            poses.append(e.T_base_platform)
            valid.append(e.valid)
        poses += [_EYE if plan is None else plan, _EYE if tag is None else tag]
        covariances = []
        for n in self.covariance:
            P = estimates[n].covariance
            covariances.append(_NO_COVARIANCE if P is None else P)
        sensors = (m.tensions, m.cable_lengths, m.cable_rates)
        status = command.status if command is not None else Status.START
        event = "; ".join(marks).replace(",", ";").replace("\n", " ")
        present = (plan is not None, tag is not None)
        self._rows.append((time, poses, valid, covariances, sensors, present, status, event))
        if len(self._rows) >= self.flush_every:
            self.flush()

    def _row_format(self, has_plan: bool, has_tag: bool) -> str:
        """The printf format of one row (%.17g round-trips every float exactly)."""
        key = (has_plan, has_tag)
        if key not in self._formats:
            f7, empty7 = ["%.17g"] * 7, [""] * 7
            cells = ["%.17g", *f7]
            for name in self.estimators:
                cells += [*f7, "%d"]
                if name in self.covariance:
                    cells += ["%.17g"] * len(COV_INDEX)
            cells += ["%.17g"] * (len(CABLE_PREFIXES) * self.n_cables)
            cells += f7 if has_plan else empty7
            cells += f7 if has_tag else empty7
            cells += ["%s", "%s"]
            self._formats[key] = ",".join(cells)
        return self._formats[key]

    def _numbers(self) -> list[list[float]]:
        """The buffered rows' numbers in column order, plan and tag included (all seven each).

        Returns:
            (rows, columns) as lists of Python floats: every column up to ``status``.
        """
        rows, k = self._rows, len(self.estimators)
        T = np.array([r[1] for r in rows])  # (rows, k + 3, 4, 4): truth, estimators, plan, tag
        pose7 = np.concatenate([T[..., :3, 3], quat_wxyz_from_matrix(T[..., :3, :3])], axis=2)
        valid = np.array([r[2] for r in rows], dtype=float).reshape(len(rows), k)
        blocks = [np.array([r[0] for r in rows])[:, None], pose7[:, 0]]
        if self.covariance:
            cov = np.array([r[3] for r in rows])[:, :, _COV_ROWS, _COV_COLS]  # (rows, c, 21)
        c = 0
        for j, name in enumerate(self.estimators):
            blocks += [pose7[:, 1 + j], valid[:, j, None]]
            if name in self.covariance:
                blocks.append(cov[:, c])
                c += 1
        sensors = np.array([r[4] for r in rows]).reshape(len(rows), -1)  # tensions, lengths, rates
        blocks += [sensors, pose7[:, k + 1], pose7[:, k + 2]]
        return np.concatenate(blocks, axis=1).tolist()

    def flush(self) -> None:
        """Write the buffered rows (floats exactly, to 17 digits) and flush the file."""
        if not self._rows:
            return
        plan_at, lines = self._plan_at, []
        for numbers, (*_, (has_plan, has_tag), status, event) in zip(
            self._numbers(), self._rows, strict=True
        ):
            # an absent pose's cells stay empty: its placeholder numbers go (the tag's first)
            if not has_tag:
                del numbers[plan_at + 7 : plan_at + 14]
            if not has_plan:
                del numbers[plan_at : plan_at + 7]
            numbers += (status, event)
            lines.append(self._row_format(has_plan, has_tag) % tuple(numbers))
        with writing(self._partial):
            self._file.write("\n".join(lines) + "\n")
            self._file.flush()
        self.rows += len(self._rows)
        self._rows = []

    def finish(self) -> None:
        """Write what is buffered, flush, ``fsync`` and close (still ``<path>.partial``)."""
        if not self._file.closed:
            self.flush()
            with writing(self._partial):
                os.fsync(self._file.fileno())
                self._file.close()

    def commit(self) -> None:
        """Give the finished file its final name."""
        self._out.commit()

    def abort(self) -> None:
        """Close without completing: what was written stays ``<path>.partial``."""
        self._rows = []
        with contextlib.suppress(OSError):
            self._file.close()

    def close(self) -> None:
        """Write what is buffered, close, and give the file its final name."""
        if not self._file.closed:
            self.finish()
            self.commit()


@dataclass(frozen=True, eq=False)
class Timeseries:
    """One run's ``timeseries.csv`` as arrays.

    Attributes:
        columns: float columns by name, in file order (NaN where the file is empty), each (n,).
        status: (n,) controller status per row (text).
        event: (n,) events and faults per row (text, mostly empty).
    """

    columns: dict[str, np.ndarray]
    status: np.ndarray
    event: np.ndarray

    @classmethod
    def load(cls, path: str | Path) -> Timeseries:
        """Read a run's ``timeseries.csv``.

        Raises:
            ValueError: the header is not the schema of :func:`header`.
        """
        path = Path(path)
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
        if not rows:
            raise ValueError(f"{path}: empty file, expected a timeseries.csv header")
        names, body = rows[0], rows[1:]
        estimators = _estimators_in(names)
        with_cov = [n for n in estimators if covariance_columns(n)[0] in names]
        expected = header(estimators, _count_cables(names), with_cov)
        if names != expected:
            raise ValueError(
                f"{path}: not a timeseries.csv header (estimators {list(estimators)}, "
                f"{_count_cables(names)} cables): got {names}"
            )
        status, event = np.array([r[-2] for r in body]), np.array([r[-1] for r in body])
        columns = {
            name: np.array([float(r[j]) if r[j] else np.nan for r in body])
            for j, name in enumerate(names[:-2])
        }
        return cls(columns, status, event)

    @property
    def t(self) -> np.ndarray:
        """Time [s], (n,)."""
        return self.columns["t"]

    @property
    def estimator_names(self) -> tuple[str, ...]:
        """Estimators in the file (from their ``<name>_valid`` columns), in file order."""
        return _estimators_in(self.columns)

    @property
    def n_cables(self) -> int:
        """Number of cables m."""
        return _count_cables(self.columns)

    def has(self, prefix: str) -> bool:
        """Whether poses named ``prefix`` (e.g. an estimator) are in the file."""
        return f"{prefix}_x" in self.columns

    def poses(self, prefix: str) -> np.ndarray:
        """Poses ``<prefix>_{x,y,z,qw,qx,qy,qz}`` as (n, 4, 4) transforms (NaN rows stay NaN)."""
        c = self.columns
        q = np.stack([c[f"{prefix}_q{k}"] for k in "wxyz"], axis=1)
        T = np.tile(np.eye(4), (len(q), 1, 1))
        T[:, :3, 3] = np.stack([c[f"{prefix}_{k}"] for k in "xyz"], axis=1)
        ok = np.all(np.isfinite(q), axis=1)
        T[ok, :3, :3] = matrix_from_quat_wxyz(q[ok])
        T[~ok] = np.nan
        return T

    def deviation(self, prefix: str, reference: str = "true") -> tuple[np.ndarray, np.ndarray]:
        """Translational [m] and rotational [rad] distance of ``prefix`` poses to ``reference``."""
        return pose_distance(self.poses(prefix), self.poses(reference))

    def covariance(self, prefix: str) -> np.ndarray:
        """An estimator's covariances as (n, 6, 6) (NaN where it gave none).

        Raises:
            KeyError: the estimator wrote no covariance.
        """
        cols = covariance_columns(prefix)
        P = np.zeros((len(self.t), 6, 6))
        for (i, j), c in zip(COV_INDEX, cols, strict=True):
            P[:, i, j] = P[:, j, i] = self.columns[c]
        return P

    def matrix(self, prefix: str) -> np.ndarray:
        """Per-cable columns ``<prefix>_1 … <prefix>_m`` (e.g. ``tension``) as (n, m)."""
        return np.stack([self.columns[c] for c in cable_columns(prefix, self.n_cables)], axis=1)


def load_timeseries(path: str | Path) -> Timeseries:
    """Read a run's ``timeseries.csv`` (:meth:`Timeseries.load`)."""
    return Timeseries.load(path)


def _estimators_in(names: Sequence[str] | dict) -> tuple[str, ...]:
    return tuple(n[: -len(VALID_SUFFIX)] for n in names if n.endswith(VALID_SUFFIX))


def _count_cables(names: Sequence[str] | dict) -> int:
    present = set(names)
    m = 0
    while f"{CABLE_PREFIXES[0]}_{m + 1}" in present:
        m += 1
    return m
