"""Where a camera-on run's CPU goes, thread by thread (Linux: ``/proc/self/task``).

Runs ``paper_pbvs`` (its ``acrobot`` camera: two blur sub-frames, one tick of latency) in this
process and reads every thread's CPU time (user + system) over a window of the run, after its
start-up. Prints, per thread, CPU milliseconds per control tick and the share of the two cores
a 25 Hz tick offers, beside the run's real-time factor over the window:

    python benchmarks/bench_camera_threads.py [--duration 20] [--skip 6] [--window 10]

Threads are named by what they are: the loop (``MainThread``), the camera's worker
(``camera_0``: forming and detection), Mesa's rasteriser (``llvmpipe-N``), Rerun's writers, and
the unnamed native ones (OpenCV's pool, among others).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
TICKS = os.sysconf("SC_CLK_TCK")


def _cpu() -> dict[int, tuple[str, float]]:
    """Each thread's (name, CPU seconds so far)."""
    out = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        out[int(task.name)] = (name, (int(fields[11]) + int(fields[12])) / TICKS)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=20.0, help="simulated seconds of the run")
    p.add_argument("--skip", type=float, default=6.0, help="wall seconds before the window")
    p.add_argument("--window", type=float, default=10.0, help="wall seconds measured")
    args = p.parse_args()
    from cdpr_twin.cli import main as cli

    names = {}
    samples: list = []

    def sample() -> None:
        time.sleep(args.skip)
        for _ in range(2):
            for t in threading.enumerate():  # Python's names for its own threads
                names[t.native_id] = t.name
            samples.append((time.perf_counter(), _cpu(), progress[-1] if progress else None))
            if len(samples) == 1:
                time.sleep(args.window)

    from cdpr_twin.sim.physics import Physics

    progress: list[float] = []  # the run's simulated time, at each advance of its physics
    advance = Physics.advance

    def advancing(self, *a, **k):
        result = advance(self, *a, **k)
        progress.append(self.time)
        return result

    Physics.advance = advancing
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        threading.Thread(target=sample, daemon=True).start()
        argv = ["run", "paper_pbvs", "--duration", str(args.duration), "--out", str(out)]
        sys.stdout = open(os.devnull, "w")  # the run's table
        try:
            cli(argv)
        finally:
            sys.stdout = sys.__stdout__
    if len(samples) < 2:
        sys.exit("the run ended before the window did: give a longer --duration")
    (t0, c0, s0), (t1, c1, s1) = samples
    wall = t1 - t0
    ticks = (s1 - s0) * 25.0 if s0 is not None and s1 is not None else float("nan")
    print(f"window {wall:.1f} s wall, {s1 - s0:.2f} s simulated: {(s1 - s0) / wall:.2f}× real time")
    print(f"{'thread':24s} {'CPU ms/tick':>12s} {'of 2 cores':>11s}")
    total = 0.0
    used = {
        tid: (names.get(tid, n), cpu - c0.get(tid, (n, 0.0))[1]) for tid, (n, cpu) in c1.items()
    }
    for label, cpu in sorted(used.values(), key=lambda x: -x[1]):
        if cpu > 0.005:
            total += cpu
            print(f"{label:24s} {1e3 * cpu / ticks:12.1f} {cpu / (2 * wall):10.0%}")
    print(f"{'all':24s} {1e3 * total / ticks:12.1f} {total / (2 * wall):10.0%}")


if __name__ == "__main__":
    main()
