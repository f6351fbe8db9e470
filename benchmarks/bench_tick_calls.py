"""How much Python one control tick runs: calls, functions and files crossed, per tick.

Run: ``python benchmarks/bench_tick_calls.py [--ticks 20] [--show-files]``.

It runs ``paper_open_loop`` (``ideal``, camera off; and as shipped: ``acrobot`` realism, camera
on) and ``paper_pbvs`` (``ideal``, camera in the loop) through the public ``run`` with a
profiler (``sys.setprofile``) on, and cuts the stream of Python calls at the run's own progress
callback, which the runner calls once after every tick. For the ticks after the first ten
(start-up and the first detections excluded) it prints, per tick, the median of:

- ``calls``: Python function calls (builtins and C functions not counted);
- ``functions``: distinct Python functions called;
- ``files``: distinct source files those functions live in (the package's and others');
- ``package files``: those of ``cdpr_twin``;
- ``switches``: calls whose caller lives in another file.

Counts, not seconds: the same on any machine for the same versions of the package and its
dependencies (NumPy's and SciPy's Python wrappers are counted as they are called).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = str(ROOT / "cdpr_twin")
SCENARIOS = {
    "paper_open_loop, ideal, no camera": ("paper_open_loop", "ideal", {"camera": False}),
    "paper_open_loop as shipped": ("paper_open_loop", None, {}),
    "paper_pbvs, ideal": ("paper_pbvs", "ideal", {}),
}
"""Label → (scenario, realism profile or ``None`` for the scenario's own, overrides)."""


@dataclass
class Tick:
    """The Python calls of one tick."""

    calls: int = 0
    switches: int = 0
    functions: Counter = field(default_factory=Counter)

    @property
    def files(self) -> set[str]:
        """The source files the tick's functions live in."""
        return {f for f, _, _ in self.functions}


class TickProfiler:
    """A ``sys.setprofile`` hook that files each Python call under the tick it happens in."""

    def __init__(self) -> None:
        self.ticks: list[Tick] = [Tick()]

    def progress(self, fraction: float, t: float) -> None:
        """The runner's per-tick callback: the calls so far belong to the tick just ended."""
        self.ticks.append(Tick())

    def __call__(self, frame, event: str, arg) -> None:
        if event != "call":
            return
        code = frame.f_code
        if code.co_filename == __file__:
            # the benchmark's own callback
            return
        tick = self.ticks[-1]
        tick.calls += 1
        tick.functions[(code.co_filename, code.co_firstlineno, code.co_name)] += 1
        caller = frame.f_back
        if caller is not None and caller.f_code.co_filename != code.co_filename:
            tick.switches += 1


def profile(name: str, realism: str | None, overrides: dict, ticks: int) -> list[Tick]:
    """The ticks of a run of ``ticks`` + 10 ticks of the scenario ``name``, after the tenth."""
    scenario = load_scenario(name)
    if realism is not None:
        scenario = scenario.with_realism(realism)
    period = scenario.model.control_period
    scenario = scenario.with_overrides(duration=(ticks + 10) * period, **overrides)
    profiler = TickProfiler()
    with tempfile.TemporaryDirectory() as out:
        sys.setprofile(profiler)
        try:
            run(scenario, Path(out), progress=profiler.progress, record_rrd=False)
        finally:
            sys.setprofile(None)
    # ticks[0] is the start-up and tick 0; the last one the run's end
    return profiler.ticks[11:-1]


def main() -> None:
    """Print the per-tick medians for each scenario."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=20, help="ticks measured per scenario")
    parser.add_argument("--show-files", action="store_true", help="list one tick's files")
    args = parser.parse_args()
    print(
        f"{'scenario':34s} {'calls':>7s} {'functions':>9s} {'files':>5s} "
        f"{'package files':>13s} {'switches':>8s}"
    )
    for label, (name, realism, overrides) in SCENARIOS.items():
        ticks = profile(name, realism, overrides, args.ticks)
        med = {
            "calls": statistics.median(t.calls for t in ticks),
            "functions": statistics.median(len(t.functions) for t in ticks),
            "files": statistics.median(len(t.files) for t in ticks),
            "package": statistics.median(
                sum(f.startswith(PACKAGE) for f in t.files) for t in ticks
            ),
            "switches": statistics.median(t.switches for t in ticks),
        }
        print(
            f"{label:34s} {med['calls']:7.0f} {med['functions']:9.0f} {med['files']:5.0f} "
            f"{med['package']:13.0f} {med['switches']:8.0f}"
        )
        if args.show_files:
            middle = ticks[len(ticks) // 2]
            for f in sorted(middle.files):
                print(f"    {f.removeprefix(str(ROOT) + '/')}")


if __name__ == "__main__":
    main()
