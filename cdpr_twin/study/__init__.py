"""Reproduce the paper's study in one command: runs, figures and a findings report.

The study: the open-loop experiment with all six estimators passive (Fig. 5), PBVS
with each estimator in the loop (Fig. 7), and the accuracy and repeatability campaign of §IV-D
(Fig. 8): 10 open-loop runs and 30 PBVS runs, 5 per estimator. One robot (the scenarios' truth
seed) throughout; each run draws its own sensor noise (run seed). The seed-1 runs are also the
runs of Fig. 5 and 7. Runs are independent processes, in parallel; a failed run is reported and
the others are kept.

Modules: :mod:`.plan` (which runs, and running them), :mod:`.analysis` (every number, from the
run files), :mod:`.findings` (the paper's claims on one robot), :mod:`.criteria` (the verdicts,
over populations only), :mod:`.report` (figures and ``report.md``), :mod:`.output_dir` (the
directory's promises: one study at a time, an earlier study's files removed first, every file
written whole).
"""

from __future__ import annotations

import multiprocessing
import time
from pathlib import Path

from cdpr_twin.files.transaction import OutputDir, others, write_json_atomic
from cdpr_twin.study.analysis import accuracy_at_p1, analyse
from cdpr_twin.study.findings import FINDINGS, Finding, evaluate
from cdpr_twin.study.output_dir import STUDY_FILES, STUDY_MARKER, clear_earlier_study
from cdpr_twin.study.plan import (
    OPEN_LOOP_SCENARIO as POPULATION_SCENARIO,
)
from cdpr_twin.study.plan import (
    Progress,
    RunSpec,
    Scenarios,
    extra_runs,
    plan,
    run_study,
    spec_scenario,
)
from cdpr_twin.study.report import make_figures, write_report

__all__ = [
    "FINDINGS",
    "Finding",
    "RunSpec",
    "Scenarios",
    "accuracy_at_p1",
    "analyse",
    "check_workers",
    "evaluate",
    "make_figures",
    "plan",
    "reproduce",
    "reproduce_runs",
    "run_study",
    "study_runs",
    "write_report",
]


def study_runs(
    runs_scale: float = 1.0,
    duration: float | None = None,
    scenarios: Scenarios | tuple[str | Path, str | Path] | None = None,
    decompose: tuple[str, ...] = (),
    other_goal: str | None = None,
) -> list[RunSpec]:
    """The study's runs, each checked: its scenario loaded with its overrides (no file touched).

    Args:
        runs_scale: factor on the repetition counts (at least one run each).
        duration: duration override of every run [s], or ``None``.
        scenarios: the (open-loop, PBVS) scenario files; default the paper's.
        decompose: per-run sources of variation to switch off in turn (extra runs).
        other_goal: a second PBVS goal (``"nominal"``/``"taught"``) for the control runs.

    Raises:
        ValueError: an option is invalid (``runs_scale``), or a run's scenario is
            (:class:`~cdpr_twin.scenario.loading.ScenarioError`: a scenario file, ``duration``, a
            ``decompose`` source or ``other_goal``).
    """
    scenarios = Scenarios(*scenarios) if scenarios is not None else Scenarios()
    specs = plan(runs_scale, duration, scenarios.open_loop, scenarios.pbvs)
    specs += extra_runs(specs, decompose, other_goal)
    for spec in specs:
        spec_scenario(spec)  # raises before any run starts, not in every run
    return specs


def check_workers(workers: int | None) -> int:
    """The number of parallel runs: ``workers``, or one per CPU when ``None``.

    Raises:
        ValueError: ``workers`` is not an integer ≥ 1.
    """
    if workers is None:
        return max(1, multiprocessing.cpu_count())
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"--workers must be an integer ≥ 1 (parallel runs), got {workers}")
    return workers


def reproduce(
    out: Path,
    workers: int | None = None,
    runs_scale: float = 1.0,
    duration: float | None = None,
    progress: Progress | None = None,
    scenarios: Scenarios | tuple[str | Path, str | Path] | None = None,
    decompose: tuple[str, ...] = (),
    other_goal: str | None = None,
    population: Path | None = None,
) -> dict:
    """Run the study and write ``runs/``, ``runs.json``, figures, ``report.json``, ``report.md``.

    Every option and every run's scenario is checked before anything runs or any file is
    touched (:func:`study_runs`); then :func:`reproduce_runs`.

    Args:
        out: output directory (created).
        workers: parallel runs (default: one per CPU).
        runs_scale: factor on the repetition counts (at least one run each).
        duration: duration override of every run [s], or ``None``.
        progress: ``progress(done, total, record)``, called as each run ends.
        scenarios: the (open-loop, PBVS) scenario files; default the paper's.
        decompose: per-run sources of variation (:data:`cdpr_twin.robot.realism.RUN_SOURCES`) to
            switch off in turn, repeating the open-loop and control-in-the-loop PBVS runs.
        other_goal: a second PBVS goal (``"nominal"``/``"taught"``) for the control runs.
        population: the population campaign's directory (:mod:`.population`): its missing
            runs are run (those there are kept) and the findings judged over it.

    Returns:
        The report numbers (as in ``report.json``), plus ``"wall_time_s"``.

    Raises:
        ValueError: an option or a run's scenario is invalid (nothing touched).
        OutputDirError: ``out`` cannot be used, another study or run owns it, or it holds a
            single run's or a campaign's outputs.
        OutputError: a file cannot be written (it is left ``*.partial``).
    """
    workers = check_workers(workers)
    specs = study_runs(runs_scale, duration, scenarios, decompose, other_goal)
    return reproduce_runs(out, specs, workers, progress, population)


def reproduce_runs(
    out: Path,
    specs: list[RunSpec],
    workers: int,
    progress: Progress | None = None,
    population: Path | None = None,
    population_progress=None,
) -> dict:
    """Claim ``out``, remove an earlier study's files, run ``specs``, write the report.

    The directory's promises are :mod:`.output_dir`': its lock held throughout (a second writer is
    refused), the earlier study's report, figures, ``runs.json`` and runs removed before any
    run starts, each file written whole, ``report.md`` last. A stop (Ctrl-C, SIGTERM) ends the
    workers and leaves the runs that finished, without ``runs.json`` or a report, but with
    ``study.json`` (written at the start), which marks the directory as a study's.

    Returns:
        The report numbers (as in ``report.json``), plus ``"wall_time_s"``.

    Raises:
        OutputDirError: ``out`` cannot be used, another study or run owns it, or it holds a
            single run's or a campaign's outputs.
        OutputError: a file cannot be written (it is left ``*.partial``).
    """
    # a single run's or a campaign's directory is refused (it would be emptied or mixed)
    owner = OutputDir(out, outputs=(), foreign=others("study"), partials=STUDY_FILES)
    owner.claim()  # the lock, then *.partial removed
    try:
        clear_earlier_study(out)
        write_json_atomic(out / STUDY_MARKER, {"command": "reproduce", "runs": len(specs)})
        start = time.perf_counter()
        records = run_study(specs, out, workers, progress)
        rep = analyse(out, records)
        figs = make_figures(out, rep, records)
        if population is not None:
            _population(rep, population, workers, population_progress)
            write_json_atomic(out / "report.json", rep)
        wall = time.perf_counter() - start
        write_report(out, rep, figs, wall)
    finally:
        owner.release()
    return {**rep, "wall_time_s": wall}


def _population(rep: dict, out: Path, workers: int, progress) -> None:
    """Run the population's missing runs; ``rep["population"]``: its numbers.

    ``report.md``'s population sections are written from them (:mod:`.population_report`).
    """
    from cdpr_twin.campaign import load_campaign, run_campaign
    from cdpr_twin.campaign.report import write_report as write_campaign_report
    from cdpr_twin.study.calibration_gauge import CALIBRATION_DIR, calibration_rows
    from cdpr_twin.study.population import (
        POPULATION_CAMPAIGN,
        population_json,
        population_report,
    )

    campaign = load_campaign(POPULATION_CAMPAIGN)
    run_campaign(campaign, out, workers, resume=True, progress=progress)
    write_campaign_report(out, campaign)  # as `cdpr-twin campaign` leaves it
    rep["population"] = population_json(population_report(out))
    rep["population"]["scenario"] = POPULATION_SCENARIO.name  # of the shipped scenarios
    if (CALIBRATION_DIR / "results.json").is_file():
        rep["population"]["calibration"] = calibration_rows(CALIBRATION_DIR, POPULATION_SCENARIO)
