"""Soak: one simulated hour without camera, resident memory sampled as it runs.

Run: ``python benchmarks/bench_soak.py [--hours H]``.

The paper's open-loop trajectory (p0 → p1 → p2 → p0, 25 s) is repeated for the whole run, with
all six estimators, the fault monitor, and every output (``timeseries.csv``, ``recording.rrd``,
``summary.json``) written to a temporary directory. The process's resident set size (RSS, from
``/proc/self/statm``) is sampled every simulated minute. Target: after the first
simulated minute RSS stays within 50 MB of its value then, over one simulated hour. It prints
the growth, its rate per simulated hour, and the real-time factor against the loop's first
minute in the same run (the baseline: a slowdown over the hour would show a leak's cost too).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario

ROOT = Path(__file__).resolve().parent.parent
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    """Resident set size of this process now [MB]."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 1e6


def soak_scenario(hours: float, tmp: Path) -> Path:
    """The paper's open-loop scenario, its trajectory repeated for ``hours``."""
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    laps = max(1, round(hours * 3600 / 25.0))
    a = text.index("waypoints = [")
    b = text.index("]\n", text.index("durations = [")) + 2
    lap = [
        "[0.284, -0.197, 0.08, 0, 0, 0]",
        "[0.284, -0.197, 0.25, 0, 0, 0]",
        "[0.112, -0.032, 0.301, -12, -10, 0]",
    ]
    waypoints = ",\n".join(["    " + w for _ in range(laps) for w in lap])
    durations = ", ".join(["10.0, 5.0, 10.0"] * laps)
    text = text[:a] + f"waypoints = [\n{waypoints}\n]\ndurations = [{durations}]\n" + text[b:]
    text = text.replace("duration = 25.0", f"duration = {laps * 25.0}")
    path = tmp / "soak.toml"
    path.write_text(text)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0, help="simulated hours (default 1)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        s = load_scenario(soak_scenario(args.hours, Path(tmp))).with_overrides(camera=False)
        samples: list[tuple[float, float, float]] = []  # (simulated s, wall s, RSS MB)
        start = time.perf_counter()

        def progress(fraction: float, t: float) -> None:
            if not samples or t >= samples[-1][0] + 60.0 - 1e-6:
                samples.append((t, time.perf_counter() - start, rss_mb()))

        result = run(s, Path(tmp) / "out", progress=progress)
        samples.append((result.summary["simulated_time_s"], result.wall_time, rss_mb()))
    (t1, w1, m1) = next(x for x in samples if x[0] >= 60.0 - 1e-6)
    t_end, w_end, m_end = samples[-1]
    peak = max(m for t, _, m in samples if t >= t1)
    growth = m_end - m1
    rate_h = growth / max(t_end - t1, 1e-9) * 3600.0
    print(f"status {result.summary['status']}, {t_end:.0f} s simulated in {w_end:.0f} s")
    print(f"RSS after the first minute {m1:.1f} MB; at the end {m_end:.1f} MB; peak {peak:.1f} MB")
    print(f"growth {growth:+.1f} MB ({rate_h:+.1f} MB per simulated hour; target: within 50 MB)")
    print(
        f"real-time factor: first minute {t1 / w1:.1f}×, whole run {t_end / w_end:.1f}× "
        f"(ratio {(t_end / w_end) / (t1 / w1):.2f})"
    )
    print("PASS" if abs(peak - m1) <= 50.0 else "FAIL: RSS grew by more than 50 MB")


if __name__ == "__main__":
    main()
