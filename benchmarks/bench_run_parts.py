"""Where one control tick of a camera-less run goes, against physics alone.

Run: ``python benchmarks/bench_run_parts.py [--repeats 3] [--realism ideal|acrobot]``.

It runs ``paper_open_loop`` with the camera off through the real runner, timing each part of
every tick with ``perf_counter`` around the calls of :meth:`cdpr_twin.run.episode.Episode.step`
(nothing else changes): physics (``Physics.advance`` of one period: MuJoCo's ``mj_step``
blocks, the swivel refreshes, the step hooks such as the fault monitor), the sensor read, each
estimator's ``update``, the tick's record (the events fired, the monitor's look, the
``TickRecord``, sinks excluded), and each sink (the metrics with the estimates' deviations, the
CSV and Rerun rows, the summary's tally). The baseline, measured in the same run: the twin alone
stepping the same period at zero rates (``bench_scenarios.physics_only``). The ratio, run /
physics alone, is physics-alone µs per tick divided by the run's µs per tick.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.recording import sinks as recorders
from cdpr_twin.run import episode, metrics, runner, summary
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import physics, sensors

ROOT = Path(__file__).resolve().parent.parent


def _timed(owner: object, name: str, label: str, acc: dict[str, float]) -> Callable[[], None]:
    """Wrap ``owner.name`` to add its wall time to ``acc[label]``; returns the undo."""
    original = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            acc[label] += time.perf_counter() - t0

    setattr(owner, name, wrapper)
    return lambda: setattr(owner, name, original)


def _estimate_timed(acc: dict[str, float]) -> Callable:
    """``RunSetup.estimate`` with each estimator's update timed."""

    def estimate(self, m):
        out = {}
        for name in self.order:
            est = self.estimators[name]
            inputs = {n: out[n] for n in est.inputs}
            t0 = time.perf_counter()
            out[name] = est.update(m, inputs) if inputs else est.update(m)
            acc[f"estimator {name}"] += time.perf_counter() - t0
        return {name: out[name] for name in self.estimators}

    return estimate


def measure(realism: str) -> tuple[dict[str, float], int, float]:
    """µs per tick of each part, the ticks, and the loop's whole µs per tick."""
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    s = s.with_realism(realism).with_overrides(camera=False)
    acc: dict[str, float] = defaultdict(float)
    undo = [
        _timed(physics.Physics, "advance", "physics (advance)", acc),
        _timed(sensors.Sensors, "read", "sensor read", acc),
        _timed(metrics.RunMetrics, "add", "sink: metrics", acc),
        _timed(recorders.Recorders, "add", "sink: CSV + Rerun rows", acc),
        _timed(summary.Tally, "add", "sink: summary tally", acc),
        _timed(episode.Episode, "_record", "record: events, monitor, tick", acc),
    ]
    original_estimate = runner.RunSetup.estimate
    runner.RunSetup.estimate = _estimate_timed(acc)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            result = runner.run(s, Path(tmp) / "run")
    finally:
        runner.RunSetup.estimate = original_estimate
        for u in undo:
            u()
    ticks = int(result.summary["ticks_recorded"])
    return {k: v / ticks * 1e6 for k, v in acc.items()}, ticks, result.wall_time / ticks * 1e6


def main() -> None:
    from bench_scenarios import physics_only  # the same baseline as the RTF benchmark

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--realism", choices=("ideal", "acrobot"), default="ideal")
    args = parser.parse_args()
    period = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").model.control_period
    base_rtf = statistics.median(physics_only(10.0) for _ in range(args.repeats))
    base_us = period / base_rtf * 1e6
    runs = [measure(args.realism) for _ in range(args.repeats)]
    loop_us = statistics.median(r[2] for r in runs)
    parts = {k: statistics.median(r[0][k] for r in runs) for k in runs[0][0]}
    # the record's time includes its sinks': each part counted once
    sinks = sum(us for k, us in parts.items() if k.startswith("sink: "))
    parts["record: events, monitor, tick"] -= sinks
    print(f"paper_open_loop, camera off, realism {args.realism}: median of {args.repeats} runs")
    print(f"physics alone (baseline): {base_us:7.0f} µs per tick ({base_rtf:.1f}× real time)")
    print(f"the run's loop:          {loop_us:7.0f} µs per tick → {base_us / loop_us:.2f}× physics")
    print(f"\n{'part':32s} {'µs/tick':>8s} {'share':>6s}")
    for name, us in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"{name:32s} {us:8.0f} {us / loop_us:6.0%}")
    rest = loop_us - sum(parts.values())
    print(f"{'the rest (controller, loop)':32s} {rest:8.0f} {rest / loop_us:6.0%}")


if __name__ == "__main__":
    main()
