"""Which runs the study makes, and running them in parallel (spawned processes).

The open-loop runs come from one scenario file, the PBVS runs from another: one set of PBVS
runs per estimator of that file (its ``in_loop`` and ``passive`` estimators), each in the loop
in turn, so an estimator added to the scenario file gets its own runs.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import NamedTuple

from cdpr_twin import SCENARIOS_DIR

OPEN_LOOP_SCENARIO = SCENARIOS_DIR / "paper_open_loop.toml"
"""The paper's open-loop experiment (Fig. 5)."""
PBVS_SCENARIO = SCENARIOS_DIR / "paper_pbvs.toml"
"""The paper's PBVS experiment (Fig. 7)."""
OPEN_LOOP_RUNS = 10
"""Open-loop repetitions of the paper's Fig. 8."""
PBVS_RUNS_PER_ESTIMATOR = 5
"""PBVS repetitions per in-loop estimator (Fig. 8: 30 runs for 6 estimators)."""
MAX_RUNS_SCALE = 100.0
"""The largest ``runs_scale`` (1000 open-loop runs): beyond it, a typo rather than a study."""

Progress = Callable[[int, int, dict], None]
"""``progress(done, total, record)``, called as each run ends."""


class Scenarios(NamedTuple):
    """The study's two scenario files.

    Attributes:
        open_loop: the open-loop experiment (Fig. 5; its first waypoint is p1).
        pbvs: the PBVS experiment (Fig. 7); its estimators are the study's.
    """

    open_loop: str | Path = OPEN_LOOP_SCENARIO
    pbvs: str | Path = PBVS_SCENARIO


@dataclass(frozen=True)
class RunSpec:
    """One run of the study.

    Attributes:
        name: unique name (its output directory under ``runs/``).
        kind: ``"open_loop"`` or ``"pbvs"``.
        scenario: scenario file.
        seed: run seed (sensor noise).
        in_loop: estimator closing the loop (PBVS).
        duration: duration override [s], or ``None``.
        record_rrd: write a Rerun recording (the figure runs only).
        without: per-run sources of variation switched off (the decomposition's runs).
        goal: the PBVS goal option (``"nominal"``/``"taught"``), or ``None``: the file's.
    """

    name: str
    kind: str
    scenario: str
    seed: int
    in_loop: str | None = None
    duration: float | None = None
    record_rrd: bool = False
    without: tuple[str, ...] = ()
    goal: str | None = None

    @property
    def group(self) -> str:
        """The campaign the run belongs to (``"main"``, ``"without <source>"``, ``"goal …"``)."""
        if self.without:
            return "without " + "+".join(self.without)
        return f"goal {self.goal}" if self.goal else "main"


def plan(
    runs_scale: float = 1.0,
    duration: float | None = None,
    open_loop: str | Path = OPEN_LOOP_SCENARIO,
    pbvs: str | Path = PBVS_SCENARIO,
) -> list[RunSpec]:
    """The runs of the study; ``runs_scale`` scales the repetition counts (at least one each).

    Args:
        runs_scale: factor on :data:`OPEN_LOOP_RUNS` and :data:`PBVS_RUNS_PER_ESTIMATOR`.
        duration: duration override of every run [s], or ``None``.
        open_loop: the open-loop scenario file.
        pbvs: the PBVS scenario file; one set of runs per estimator it lists.

    Raises:
        ValueError: ``runs_scale`` is not a number in (0, :data:`MAX_RUNS_SCALE`].
        cdpr_twin.scenario.loading.ScenarioError: a scenario file is invalid.
    """
    from cdpr_twin.scenario.loading import load_scenario

    if not (math.isfinite(runs_scale) and 0 < runs_scale <= MAX_RUNS_SCALE):
        raise ValueError(
            f"--runs-scale must be > 0 and ≤ {MAX_RUNS_SCALE:g}, got {runs_scale} "
            "(1 is the paper's counts, 0.1 a quick check)"
        )
    n_open = max(1, round(OPEN_LOOP_RUNS * runs_scale))
    n_pbvs = max(1, round(PBVS_RUNS_PER_ESTIMATOR * runs_scale))
    ol, pb = str(open_loop), str(pbvs)
    estimators = load_scenario(pb).estimators.names
    specs = [
        RunSpec(f"open_loop_seed{k}", "open_loop", ol, k, None, duration, k == 1)
        for k in range(1, n_open + 1)
    ]
    specs += [
        RunSpec(f"pbvs_{name}_seed{k}", "pbvs", pb, k, name, duration, k == 1)
        for name in estimators
        for k in range(1, n_pbvs + 1)
    ]
    return specs


def extra_runs(
    specs: list[RunSpec],
    decompose: tuple[str, ...] = (),
    goal: str | None = None,
    in_loop: str = "control",
) -> list[RunSpec]:
    """More runs for the repeatability decomposition and the other PBVS goal.

    Args:
        specs: the main runs (:func:`plan`).
        decompose: per-run sources of variation; each repeats the main open-loop runs and the
            ``in_loop`` PBVS runs with that source off.
        goal: the other PBVS goal: repeats the ``in_loop`` PBVS runs with it.
        in_loop: the PBVS runs repeated (the paper's best in-loop estimator).
    """
    base = [s for s in specs if s.kind == "open_loop" or s.in_loop == in_loop]
    out = [
        replace(s, name=f"{s.name}_without_{source}", without=(source,), record_rrd=False)
        for source in decompose
        for s in base
    ]
    out += [
        replace(s, name=f"{s.name}_goal_{goal}", goal=goal, record_rrd=False)
        for s in base
        if goal is not None and s.kind == "pbvs"
    ]
    return out


def spec_scenario(spec: RunSpec):
    """The scenario a spec runs: its file with the spec's overrides (``Scenario``).

    Raises:
        cdpr_twin.scenario.loading.ScenarioError: the file or an override is invalid.
    """
    from cdpr_twin.scenario.loading import load_scenario

    s = load_scenario(spec.scenario).with_overrides(
        seed=spec.seed, in_loop=spec.in_loop, duration=spec.duration
    )
    s = s.without(*spec.without)
    return s if spec.goal is None else s.with_controller_options(goal=spec.goal)


def _run_one(spec: RunSpec, runs_dir: str) -> dict:
    """Worker (a spawned process): run one spec; never raise, report instead.

    Ctrl-C is ignored here: the terminal sends it to the worker too, and the study stops its
    workers itself (SIGTERM), cancelling the queued runs.
    """
    from cdpr_twin.run.runner import run

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    out = Path(runs_dir) / spec.name
    try:
        result = run(spec_scenario(spec), out, record_rrd=spec.record_rrd)
        return {
            **asdict(spec),
            "ok": True,
            "status": result.summary["status"],
            "wall_time_s": result.wall_time,
            "dir": str(out),
        }
    except Exception as exc:  # keep the others' results: this one is reported as failed
        return {
            **asdict(spec),
            "ok": False,
            "status": f"failed: {type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
            "dir": str(out),
        }


def run_study(
    specs: list[RunSpec], out: Path, workers: int, progress: Progress | None = None
) -> list[dict]:
    """Run every spec in ``workers`` spawned processes; writes ``runs.json`` (whole).

    A stop (Ctrl-C, SIGTERM as :class:`~cdpr_twin.files.transaction.Terminated`) or any error ends
    the
    workers and cancels the queued runs before it propagates; no ``runs.json`` is written, and
    the runs under way leave no lock or ``*.partial`` file.

    Returns:
        One record per run, in the order of ``specs``: the spec's fields, ``ok``, ``status``,
        ``dir`` (the run's output directory), and ``wall_time_s`` or ``traceback``.

    Raises:
        OutputError: ``runs/`` or ``runs.json`` cannot be written.
    """
    from cdpr_twin.campaign.executor import run_local  # the one engine of parallel runs
    from cdpr_twin.files.transaction import sweep_abandoned, write_json_atomic, writing

    runs_dir = out / "runs"
    with writing(runs_dir):
        runs_dir.mkdir(parents=True, exist_ok=True)
    records = []
    # closed on leaving, however: a stop raised here (in progress) ends the workers too
    try:
        with contextlib.closing(run_local(_run_one, specs, workers, str(runs_dir))) as results:
            for done, record in enumerate(results, 1):
                records.append(record)
                if progress is not None:
                    progress(done, len(specs), record)
    except BaseException:
        sweep_abandoned(runs_dir)  # the runs under way: their lock and *.partial files
        raise
    order = {s.name: i for i, s in enumerate(specs)}
    records.sort(key=lambda r: order[r["name"]])
    # the file names each run's directory relative to the study's: it stays true wherever the
    # study was run from, and wherever the directory is moved (the notebook reads it so)
    write_json_atomic(out / "runs.json", [{**r, "dir": relative_dir(r, out)} for r in records])
    return records


def relative_dir(record: dict, out: Path) -> str:
    """A run record's directory, relative to the study's directory ``out`` (POSIX form)."""
    return Path(os.path.relpath(Path(record["dir"]).resolve(), Path(out).resolve())).as_posix()


def with_dirs_in(out: Path, records: list[dict]) -> list[dict]:
    """Records whose ``dir`` is a path to open: a relative one (``runs.json``) joined to ``out``."""
    return [{**r, "dir": str(Path(out) / r["dir"])} for r in records]
