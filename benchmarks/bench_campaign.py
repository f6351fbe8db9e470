"""Campaign throughput: runs per minute with 1, 2 and all workers, local vs Ray, same campaign.

Run: ``python benchmarks/bench_campaign.py [--runs N] [--duration S]``.

The campaign: the paper's open-loop scenario without camera, ``--duration`` seconds per run,
``--runs`` robots (``truth.seed`` random). Each configuration runs the whole campaign into a
fresh directory; the baseline is the local executor with one worker, measured in the same
run: scaling efficiency = (runs/min with k workers) / (k × runs/min with one). Ray runs the
same tasks on a local cluster of all cores (skipped, and said so, if Ray is not installed).
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
import time
from pathlib import Path

from cdpr_twin.campaign import load_campaign, run_campaign

ROOT = Path(__file__).resolve().parent.parent


def campaign_file(tmp: Path, runs: int, duration: float) -> Path:
    """The benchmark's campaign file."""
    path = tmp / "bench.toml"
    path.write_text(
        f'name = "bench"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\nseed = 1\n'
        f'samples = {runs}\n[overrides]\n"sensors.camera" = false\nduration = {duration}\n'
        '[[axes]]\nkey = "truth.seed"\ndraw = "integers"\nlow = 1\nhigh = 1000000\n'
    )
    return path


def runs_per_minute(campaign, out: Path, workers: int, ray: bool) -> float:
    """Runs per wall-clock minute of the whole campaign (process start-up included)."""
    start = time.perf_counter()
    info = run_campaign(campaign, out, workers=workers, ray_address=True if ray else False)
    assert info["ran_now"] == len(campaign.tasks)
    return len(campaign.tasks) / (time.perf_counter() - start) * 60.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=16, help="runs per configuration")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated s per run")
    args = parser.parse_args()
    cores = multiprocessing.cpu_count()
    with tempfile.TemporaryDirectory() as tmp:
        campaign = load_campaign(campaign_file(Path(tmp), args.runs, args.duration))
        base = runs_per_minute(campaign, Path(tmp) / "w1", 1, False)
        print(f"local, 1 worker: {base:.1f} runs/min (baseline)")
        for k in sorted({2, cores} - {1}):
            rate = runs_per_minute(campaign, Path(tmp) / f"w{k}", k, False)
            print(f"local, {k} workers: {rate:.1f} runs/min, efficiency {rate / (k * base):.2f}")
        try:
            import ray  # noqa: F401
        except ImportError:
            print("ray: not installed (pip install -e '.[ray]'): skipped")
            return
        rate = runs_per_minute(campaign, Path(tmp) / "ray", cores, True)
        print(f"ray, {cores} CPUs: {rate:.1f} runs/min, {rate / base:.2f}× one local worker")


if __name__ == "__main__":
    main()
