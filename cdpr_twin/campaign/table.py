"""A campaign's results: one row per run, in Parquet, written as the runs end.

Rows are buffered and written as complete part files (``parts/part-NNNNN.parquet``, each
written as ``*.partial`` and renamed), so the table on disk is valid at every instant — after a
crash, Ctrl-C or SIGKILL at most the buffered rows are lost, and those runs are run again by
``--resume``. When a campaign ends (or is stopped) the parts are gathered into
``results.parquet`` (also written whole, then renamed)::

    import pandas as pd; runs = pd.read_parquet("campaign_out/results.parquet")

Columns (:func:`flatten`): ``run_id``, ``block``, ``name``, ``param.<dotted key>`` (each varied
value), ``status``, ``ok``, ``error``, ``wall_time_s``, ``simulated_time_s``, ``seed``,
``truth_seed``, ``in_loop``, ``fault``, ``final_t_m``/``final_r_deg`` (end vs the controller's
goal), per estimator ``est.<name>.{max_t_m, max_r_deg, rms_t_m, rms_r_deg, final_t_m,
final_r_deg, invalid}``, per checkpoint ``cp<k>.{t_m, r_deg, x, y, z, rx, ry, rz}`` (truth vs
the waypoint, and where the platform truly was [m, deg]), and ``summary`` (the run's whole
``summary.json`` as text).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cdpr_twin.files.transaction import (
    OutputDirError,
    OutputError,
    Partial,
    finite_or_null,
    fsync_dir,
    writing,
)

PARTS = "parts"
RESULTS = "results.parquet"


def _param(value: Any) -> Any:
    if isinstance(value, bool | int | float | str):
        return value
    return json.dumps(value, sort_keys=True)


def flatten(task_fields: dict, summary: dict | None, error: str = "", wall: float = math.nan):
    """One table row from a run's summary (or its error).

    Args:
        task_fields: ``run_id``, ``block``, ``name`` and ``params`` of the task.
        summary: the run's ``summary.json`` content, or ``None`` when it failed.
        error: the failure, in one line ("" when it ran).
        wall: wall-clock seconds the run took.
    """
    row: dict[str, Any] = {k: task_fields[k] for k in ("run_id", "block", "name")}
    row |= {f"param.{k}": _param(v) for k, v in task_fields["params"].items()}
    s = summary or {}
    faults = s.get("faults") or [{}]
    row |= {
        "status": s.get("status", f"failed: {error}"),
        "ok": summary is not None,
        "error": error,
        "wall_time_s": float(wall),
        "simulated_time_s": float(s.get("simulated_time_s", math.nan)),
        "seed": int(s.get("seed", -1)),
        "truth_seed": int(s.get("truth_seed", -1)),
        "in_loop": str(s.get("in_loop", "")),
        "fault": str(faults[0].get("kind", "")),
    }
    goal = s.get("final_error_vs_goal") or {}
    row["final_t_m"] = float(goal.get("translation_m", math.nan))
    row["final_r_deg"] = float(goal.get("rotation_deg", math.nan))
    keys = (
        "max_translation_m",
        "max_rotation_deg",
        "rms_translation_m",
        "rms_rotation_deg",
        "final_translation_m",
        "final_rotation_deg",
    )
    short = ("max_t_m", "max_r_deg", "rms_t_m", "rms_r_deg", "final_t_m", "final_r_deg")
    for name, e in s.get("estimators", {}).items():
        for k, c in zip(keys, short, strict=True):
            row[f"est.{name}.{c}"] = math.nan if e[k] is None else float(e[k])
        row[f"est.{name}.invalid"] = int(e["invalid_updates"])
    for i, cp in enumerate(s.get("segment_ends", []), 1):
        row[f"cp{i}.t_m"] = float(cp["truth_vs_waypoint"]["translation_m"])
        row[f"cp{i}.r_deg"] = float(cp["truth_vs_waypoint"]["rotation_deg"])
        for axis, v in zip(("x", "y", "z", "rx", "ry", "rz"), cp["true_pose"], strict=True):
            row[f"cp{i}.{axis}"] = float(v)
    row["summary"] = "" if summary is None else json.dumps(finite_or_null(summary), allow_nan=False)
    return row


class ResultTable:
    """The campaign's table in ``out``: rows appended, written in complete parts.

    Args:
        out: the campaign's output directory.
        every: rows buffered before a part is written.
        interval: seconds after which buffered rows are written anyway.
    """

    def __init__(self, out: Path, every: int = 20, interval: float = 10.0) -> None:
        self.out, self.every, self.interval = Path(out), every, interval
        self._flushed = time.monotonic()
        self.parts = self.out / PARTS
        self._rows: list[dict] = []
        if self.parts.is_symlink():  # its parts would be written wherever it points
            raise OutputDirError(
                f"{self.parts} is a symbolic link; a campaign writes its parts into a directory "
                "of its own: remove the link, or choose another --out"
            )
        with writing(self.parts):
            self.parts.mkdir(parents=True, exist_ok=True)
        self._next = 1 + max((int(p.stem.split("-")[1]) for p in self._files()), default=0)

    def _files(self) -> list[Path]:
        return sorted(self.parts.glob("part-*.parquet"))

    def done_ids(self) -> set[str]:
        """Run ids already in the table (their runs ended, ran or failed)."""
        ids: set[str] = set()
        for path in self._files():
            ids.update(read_parquet(path, ["run_id"]).column("run_id").to_pylist())
        return ids

    def add(self, row: dict) -> None:
        """Buffer a row; write a part when ``every`` are buffered or ``interval`` has passed."""
        self._rows.append(row)
        if len(self._rows) >= self.every or time.monotonic() - self._flushed >= self.interval:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows as one complete part file."""
        if not self._rows:
            return
        import pyarrow as pa

        path = self.parts / f"part-{self._next:05d}.parquet"
        # every row's columns (pyarrow's from_pylist would take the first row's: a failed run
        # first in a part would drop the others' metrics); a column a row lacks is null there
        names = list(dict.fromkeys(k for row in self._rows for k in row))
        _write(pa.table({k: [row.get(k) for row in self._rows] for k in names}), path)
        self._next += 1
        self._rows = []
        self._flushed = time.monotonic()

    def gather(self, order: Sequence[str] = ()) -> Path:
        """Write every part into ``results.parquet`` (whole, then renamed); returns its path.

        Args:
            order: the campaign's run ids in its task order: the rows follow it (runs end in
                an order that depends on the workers; the table must not), others last by id.
        """
        self.flush()
        table = load_parts(self.parts)
        rank = {run_id: i for i, run_id in enumerate(order)}
        ids = table.column("run_id").to_pylist()
        table = table.take(
            sorted(range(len(ids)), key=lambda j: (rank.get(ids[j], len(rank)), ids[j]))
        )
        path = self.out / RESULTS
        _write(table, path)
        return path


def _write(table, path: Path) -> None:
    import pyarrow.parquet as pq

    from cdpr_twin.provenance import software

    # what computed the rows, in the file's own metadata (key b"cdpr_twin.software", JSON)
    meta = {**(table.schema.metadata or {}), b"cdpr_twin.software": json.dumps(software())}
    table = table.replace_schema_metadata(meta)
    out = Partial(path)  # created afresh, never through a link; pyarrow writes into it
    with writing(out.partial), out.file("wb") as f:
        pq.write_table(table, f)
        f.flush()
        os.fsync(f.fileno())
    out.commit()
    with contextlib.suppress(OutputError):  # (some filesystems cannot fsync a directory)
        fsync_dir(path.parent)


def read_parquet(path: Path, columns: list[str] | None = None):
    """One Parquet file of a campaign's table, as a ``pyarrow.Table``.

    Raises:
        OutputDirError: it is not a readable Parquet file (damaged after it was written: parts
            are renamed only when whole), naming it and the fix.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError) as exc:
        raise OutputDirError(
            f"{path} is not a readable Parquet file ({str(exc).splitlines()[0]}); delete it "
            "and run with --resume to run its runs again"
        ) from None


def load_parts(parts: Path):
    """Every part file of a table, as one ``pyarrow.Table`` (columns unified; missing: null)."""
    import pyarrow as pa

    tables = [read_parquet(p) for p in sorted(Path(parts).glob("part-*.parquet"))]
    if not tables:
        raise OutputError(Path(parts), "no results yet")
    # permissive: an axis [0, 0.5] gives int64 parts and double parts (each part's types are
    # its own rows'), merged as double
    return pa.concat_tables(tables, promote_options="permissive")


def load_table(out: str | Path):
    """A campaign's results as a ``pyarrow.Table`` (``.to_pandas()`` for a DataFrame).

    Reads ``results.parquet`` when the campaign ended, else the parts written so far.
    """
    out = Path(out)
    if (out / RESULTS).is_file():
        return read_parquet(out / RESULTS)
    return load_parts(out / PARTS)
