"""A tick's cost beyond physics, against an earlier revision, measured in one run.

Run: ``python benchmarks/bench_tick_overhead.py [--before REV] [--repeats 5]``.

It runs ``paper_open_loop`` (``ideal``, camera off) through the public ``run`` and, as the
baseline, the twin alone stepping the same control period at zero rates and reading its sensors
(``bench_scenarios.physics_only``'s loop). Each measurement is a fresh interpreter; with
``--before``, the revision ``REV`` is checked out into a temporary git worktree and measured in
turns with this checkout (before, after, before, after, …), so that both see the same machine
at the same time. Each interpreter times three pairs (the run, then physics alone, back to
back). Per variant it prints medians over all pairs: physics alone and the run, in µs per
tick; their ratio pair by pair (the run's speed as a fraction of physics alone's); and the
overhead, run − physics alone, the Python a tick runs around the physics (estimators,
controller, monitor, records).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def measure(pairs: int = 3) -> list[dict[str, float]]:
    """µs per tick of the run and of physics alone, ``pairs`` times in turns, in this interpreter.

    Each pair times the run, then physics alone for as many ticks, back to back: a machine
    that slows down for a while slows both, so a pair's ratio holds better than either time.
    """
    import numpy as np

    import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
    from cdpr_twin.run.runner import run
    from cdpr_twin.scenario.loading import load_scenario
    from cdpr_twin.sim.twin import Twin

    s = load_scenario("paper_open_loop").with_realism("ideal").with_overrides(camera=False)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        run(s, Path(tmp) / "warm-up")
        for k in range(pairs):
            result = run(s, Path(tmp) / f"run-{k}")
            ticks = int(result.summary["ticks_recorded"])
            # bench_scenarios.physics_only's loop, kept here: that module imports what an
            # older revision's package may not have
            with Twin(
                s.model.file,
                deviations=s.truth,
                camera=False,
                align_every=s.model.align_every,
                timestep=s.model.timestep,
            ) as twin:
                twin.reset(s.start_pose)
                t0 = time.perf_counter()
                for _ in range(ticks):
                    twin.advance(s.model.control_period, np.zeros(twin.physics.n_cables))
                    twin.sense()
                physics = (time.perf_counter() - t0) / ticks
            rows.append({"physics_us": physics * 1e6, "run_us": result.wall_time / ticks * 1e6})
    return rows


def _measured(root: Path) -> list[dict[str, float]]:
    """:func:`measure` in a fresh interpreter that imports ``cdpr_twin`` from ``root``."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run(
        [sys.executable, __file__, "--measure"],
        env=env,
        cwd=tempfile.gettempdir(),
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.splitlines()[-1])


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    """Measure this checkout (and ``--before``'s revision, in turns) and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", help="a git revision to measure in turns with this checkout")
    parser.add_argument("--repeats", type=int, default=5, help="measurements per variant")
    parser.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure()))
        return
    variants = {"this checkout": ROOT}
    with tempfile.TemporaryDirectory() as tmp:
        if args.before:
            before = Path(tmp) / "before"
            add = ["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(before)]
            subprocess.run([*add, args.before], check=True)
            variants = {f"before ({args.before})": before, **variants}
        try:
            runs: dict[str, list[dict[str, float]]] = {name: [] for name in variants}
            for _ in range(args.repeats):
                for name, root in variants.items():
                    runs[name] += _measured(root)
        finally:
            if args.before:
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(before)],
                    check=False,
                )
    print(f"paper_open_loop, ideal, camera off; {_cpu()}, {os.cpu_count()} cores")
    print(
        f"medians of {args.repeats} interpreters × 3 pairs, µs per tick (variants in turns);"
        " ratio: physics alone / run, pair by pair\n"
    )
    print(f"{'variant':28s} {'physics':>8s} {'run':>8s} {'ratio':>6s} {'overhead':>9s}")
    for name, rows in runs.items():
        physics = statistics.median(r["physics_us"] for r in rows)
        run_us = statistics.median(r["run_us"] for r in rows)
        ratio = statistics.median(r["physics_us"] / r["run_us"] for r in rows)
        overhead = statistics.median(r["run_us"] - r["physics_us"] for r in rows)
        print(f"{name:28s} {physics:8.0f} {run_us:8.0f} {ratio:6.2f} {overhead:9.0f}")


if __name__ == "__main__":
    main()
