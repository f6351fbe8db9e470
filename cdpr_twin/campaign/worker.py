"""One campaign run in a worker process: build the scenario, run it, return its table row."""

from __future__ import annotations

import time
import traceback
from dataclasses import asdict
from pathlib import Path

from cdpr_twin.campaign.spec import Task
from cdpr_twin.campaign.table import flatten


def run_task(task: Task, runs_dir: str) -> dict:
    """Run one task; never raises: a failure is a row with its error.

    Args:
        task: the run.
        runs_dir: where per-run artefacts go (``<runs_dir>/<run_id>/``), when the task keeps
            any (``artefacts``: ``csv`` writes ``timeseries.csv`` and ``summary.json``,
            ``all`` also ``recording.rrd``).

    Returns:
        The row (:func:`cdpr_twin.campaign.table.flatten`).
    """
    from cdpr_twin.plugins import unannounced
    from cdpr_twin.run.runner import run
    from cdpr_twin.scenario.loading import scenario_from_data

    fields = {k: v for k, v in asdict(task).items() if k in ("run_id", "block", "name", "params")}
    out = None if task.artefacts == "none" else Path(runs_dir) / task.run_id
    start = time.perf_counter()
    try:
        with unannounced():  # the campaign named its plugins as it read its runs
            s = scenario_from_data(task.data, task.source)
        result = run(s, out, record_rrd=task.artefacts == "all")
    except (Exception, SystemExit) as exc:  # the campaign goes on: a row with its error
        last = traceback.extract_tb(exc.__traceback__)[-1]
        where = f" ({Path(last.filename).name}:{last.lineno})"
        error = f"{type(exc).__name__}: {exc}{where}".replace("\n", " ")
        return flatten(fields, None, error, time.perf_counter() - start)
    return flatten(fields, result.summary, "", result.wall_time)
