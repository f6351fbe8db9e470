"""Reproduce the paper's study in one command: runs, figures and a findings report.

The study (DESIGN §8): the open-loop experiment with all six estimators passive (Fig. 5), PBVS
with each estimator in the loop (Fig. 7), and the accuracy and repeatability campaign of §IV-D
(Fig. 8): 10 open-loop runs and 30 PBVS runs, 5 per estimator. One robot (the scenarios' truth
seed) throughout; each run draws its own sensor noise (run seed). The seed-1 runs are also the
runs of Fig. 5 and 7. Runs are independent processes, in parallel; a failed run is reported and
the others are kept.

Modules: :mod:`.plan` (which runs, and running them), :mod:`.analysis` (every number, from the
run files), :mod:`.findings` (the paper's claims and their verdicts), :mod:`.report` (figures
and ``report.md``).
"""

from __future__ import annotations

import multiprocessing
import time
from pathlib import Path

from cdpr_twin.study.analysis import accuracy_at_p1, analyse
from cdpr_twin.study.findings import FINDINGS, Finding, evaluate
from cdpr_twin.study.plan import Progress, RunSpec, Scenarios, extra_runs, plan, run_study
from cdpr_twin.study.report import make_figures, write_report

__all__ = [
    "FINDINGS",
    "Finding",
    "RunSpec",
    "Scenarios",
    "accuracy_at_p1",
    "analyse",
    "evaluate",
    "make_figures",
    "plan",
    "reproduce",
    "run_study",
    "write_report",
]


def reproduce(
    out: Path,
    workers: int | None = None,
    runs_scale: float = 1.0,
    duration: float | None = None,
    progress: Progress | None = None,
    scenarios: Scenarios | tuple[str | Path, str | Path] | None = None,
    decompose: tuple[str, ...] = (),
    other_goal: str | None = None,
) -> dict:
    """Run the study and write ``runs/``, ``runs.json``, figures, ``report.json``, ``report.md``.

    Args:
        out: output directory (created).
        workers: parallel runs (default: one per CPU).
        runs_scale: factor on the repetition counts (at least one run each).
        duration: duration override of every run [s], or ``None``.
        progress: ``progress(done, total, record)``, called as each run ends.
        scenarios: the (open-loop, PBVS) scenario files; default the paper's.
        decompose: per-run sources of variation (:data:`cdpr_twin.realism.RUN_SOURCES`) to
            switch off in turn, repeating the open-loop and control-in-the-loop PBVS runs.
        other_goal: a second PBVS goal (``"nominal"``/``"taught"``) for the control runs.

    Returns:
        The report numbers (as in ``report.json``), plus ``"wall_time_s"``.
    """
    scenarios = Scenarios(*scenarios) if scenarios is not None else Scenarios()
    workers = workers or max(1, multiprocessing.cpu_count())
    specs = plan(runs_scale, duration, scenarios.open_loop, scenarios.pbvs)
    specs += extra_runs(specs, decompose, other_goal)
    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    records = run_study(specs, out, workers, progress)
    rep = analyse(out, records)
    figs = make_figures(out, rep, records)
    wall = time.perf_counter() - start
    write_report(out, rep, figs, wall)
    return {**rep, "wall_time_s": wall}
