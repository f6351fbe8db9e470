"""Campaigns: many runs of varied scenarios, on local cores or a Ray cluster, into one table.

``cdpr-twin campaign CAMPAIGN.toml`` (:func:`run_campaign`): the campaign file
(:mod:`.spec`) is expanded into validated tasks before anything runs; the tasks run in spawned
local processes or on Ray (:mod:`.executor`); each run's row is appended to a Parquet table
(:mod:`.table`) as it ends; a report with figures is computed from the table (:mod:`.report`).
``--resume`` skips the runs already in the table: after a crash or a stop only the missing
runs run, and a finished campaign runs nothing.
"""

from __future__ import annotations

import json
import multiprocessing
import time
from collections.abc import Callable
from pathlib import Path

from cdpr_twin.campaign.executor import ExecutorError, run_local, run_ray
from cdpr_twin.campaign.keys import changed_inputs, digests, input_files
from cdpr_twin.campaign.report import report_files
from cdpr_twin.campaign.spec import Campaign, CampaignError, Task, load_campaign
from cdpr_twin.campaign.table import RESULTS, ResultTable, load_table
from cdpr_twin.campaign.worker import run_task
from cdpr_twin.files.transaction import (
    Marker,
    OutputDir,
    OutputDirError,
    Terminated,
    others,
    sweep_abandoned,
    write_json_atomic,
    writing,
)
from cdpr_twin.provenance import software
from cdpr_twin.run.interrupts import interruption, shielded

CAMPAIGN_FILES = (RESULTS, "report.md", "*.png", "campaign.json")
"""Patterns of a campaign's own files beside its ``parts/`` and ``runs/``."""
CAMPAIGN_OWNED = (RESULTS, "report.md", "distribution.png", "effect_*.png", "campaign.json")
"""What a campaign replaces: in a directory without its ``campaign.json``, someone else's."""
CAMPAIGN_MARKER = Marker("campaign.json", frozenset({"campaign", "source", "status", "runs"}))
"""``campaign.json``, written as a campaign starts (``running``) and as it ends."""

__all__ = [
    "CAMPAIGN_FILES",
    "Campaign",
    "CampaignError",
    "ExecutorError",
    "Task",
    "load_campaign",
    "load_table",
    "run_campaign",
]

Progress = Callable[[int, int, dict], None]
"""``progress(done, total, row)``, called as each run ends."""


def run_campaign(
    campaign: Campaign,
    out: Path,
    workers: int | None = None,
    ray_address: str | bool | None = False,
    resume: bool = False,
    progress: Progress | None = None,
) -> dict:
    """Run a campaign's missing runs and write its table and ``campaign.json``.

    Args:
        campaign: a loaded campaign (:func:`load_campaign`).
        out: output directory: ``parts/``, ``results.parquet``, ``campaign.json``, ``runs/``
            (per-run artefacts, where the campaign asks for them).
        workers: parallel runs (default: every CPU, or every CPU of the Ray cluster).
        ray_address: ``False``: local processes; ``None`` or ``True``: a local Ray cluster;
            a string: the address of a Ray cluster to join.
        resume: run only the runs not yet in the table; without it a directory that already
            holds results is refused.
        progress: called as each run ends.

    Returns:
        ``campaign.json``'s content: counts, timings, the table's path.

    Raises:
        OutputDirError: ``out`` is in use, or holds results and ``resume`` is off.
        ExecutorError: Ray is asked for but cannot start.
    """
    # a single run's or a study's directory is refused (it would be emptied or mixed)
    owner = OutputDir(
        out,
        outputs=(),
        foreign=others("campaign"),
        partials=CAMPAIGN_FILES,
        owned=CAMPAIGN_OWNED,
        marker=CAMPAIGN_MARKER,
        inputs=(campaign.source,),
    )
    owner.claim()
    try:
        # parts of ≤ 1/10 of the runs (≤ 20 rows): a kill loses at most that much work
        table = ResultTable(out, every=max(1, min(20, len(campaign.tasks) // 10)))
        done_ids = table.done_ids()
        if done_ids and not resume:
            raise OutputDirError(
                f"{out} already holds {len(done_ids)} runs of a campaign; pass --resume to run "
                "only the missing ones, or choose another --out"
            )
        if strangers := done_ids - {t.run_id for t in campaign.tasks}:
            raise OutputDirError(
                f"{out} holds {len(strangers)} runs that campaign {campaign.name!r} does not "
                "have (another campaign's, or this file's before an edit): resuming would mix "
                "them into one table; choose another --out"
            )
        inputs = digests(input_files(campaign.tasks))
        if done_ids and (changed := changed_inputs(_recorded_inputs(out), inputs)):
            raise OutputDirError(
                f"{changed[0]} changed since the runs in {out} were made: resuming would mix "
                "two versions of it in one table; restore it, or choose another --out"
            )
        todo = [t for t in campaign.tasks if t.run_id not in done_ids]
        return _execute(campaign, out, table, todo, workers, ray_address, progress, inputs)
    finally:
        owner.release()


def _recorded_inputs(out: Path) -> dict[str, str]:
    """The input files' digests ``campaign.json`` recorded (none from an older version)."""
    try:
        recorded = json.loads((out / "campaign.json").read_text(encoding="utf-8"))["inputs"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return recorded if isinstance(recorded, dict) else {}


def _outdated(out: Path, campaign, todo: list, inputs: dict) -> None:
    """Before new runs, what described the runs so far goes: ``campaign.json`` says running.

    The table, report and figures would be stale under their final names (the parts keep the
    rows; the end of the campaign, or a ``--resume`` after a failure, writes them anew).
    """
    for path in [out / RESULTS, *report_files(out)]:
        with writing(path):
            path.unlink(missing_ok=True)
    state = {"campaign": campaign.name, "source": str(campaign.source), "status": "running"}
    write_json_atomic(
        out / "campaign.json",
        {
            **state,
            "runs": len(campaign.tasks),
            "to_run": len(todo),
            "inputs": inputs,
            "software": software(),
        },
    )


def _execute(campaign, out, table, todo, workers, ray_address, progress, inputs) -> dict:
    if todo:
        _outdated(Path(out), campaign, todo, inputs)
    runs_dir = str(Path(out) / "runs")
    start, n, status = time.perf_counter(), 0, "completed"
    if ray_address is False:
        rows = run_local(run_task, todo, workers or multiprocessing.cpu_count(), runs_dir)
    else:
        address = ray_address if isinstance(ray_address, str) else None
        rows = run_ray(run_task, todo, workers, address, runs_dir)
    try:
        for row in rows:
            table.add(row)
            n += 1
            if progress is not None:
                progress(n, len(todo), row)
    except KeyboardInterrupt as exc:  # (a SIGTERM that Ray re-raised as a plain Ctrl-C too)
        stop = interruption(exc)
        # a KeyboardInterrupt is a stop itself
        assert stop is not None
        status = "terminated" if isinstance(stop, Terminated) else "interrupted"
        if stop is exc:
            raise
        raise stop from None
    except BaseException:  # e.g. a worker lost: the campaign.json must not say completed
        status = "failed"
        raise
    finally:
        with shielded():  # a second Ctrl-C waits: the workers end, campaign.json says how
            if status != "completed":
                rows.close()  # the workers end, if a stop came between two results
                wait = 0.0 if ray_address is False else 10.0  # Ray's shutdown does not wait
                sweep_abandoned(Path(runs_dir), wait)  # the runs under way: lock, *.partial
            if n or not (Path(out) / RESULTS).exists():
                table.flush()
            summary = {
                "campaign": campaign.name,
                "source": str(campaign.source),
                "status": status,
                "runs": len(campaign.tasks),
                "ran_now": n,
                "skipped_done": len(campaign.tasks) - len(todo),
                "wall_time_s": time.perf_counter() - start,
                "executor": "local" if ray_address is False else "ray",
                "inputs": inputs,  # the files the runs read: a --resume checks them
                "software": software(),
            }
            if any(Path(out, "parts").glob("part-*.parquet")):
                summary["table"] = str(table.gather([t.run_id for t in campaign.tasks]))
            write_json_atomic(Path(out) / "campaign.json", summary)
    return summary
