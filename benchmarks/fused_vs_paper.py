"""Does ``fused`` beat every single estimator on the paper's two experiments?

Runs ``paper_open_loop`` and ``paper_pbvs`` (control in the loop; the ``acrobot`` profile, the
files' robot, camera on) with ``fused`` beside the paper's six estimators, all passive, and
prints each one's RMS translational and rotational deviation from ground truth over the run.

    python benchmarks/fused_vs_paper.py [--duration S] [--seed N] [--out DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from cdpr_twin.recording.timeseries import load_timeseries
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario

ROOT = Path(__file__).resolve().parent.parent


def rms_deviations(out: Path) -> dict[str, tuple[float, float]]:
    """RMS translation [mm] and rotation [deg] of each estimator over a run's ticks."""
    ts = load_timeseries(out / "timeseries.csv")
    result = {}
    for name in ts.estimator_names:
        dt, dr = ts.deviation(name)
        result[name] = (
            1e3 * float(np.sqrt(np.mean(dt**2))),
            float(np.degrees(np.sqrt(np.mean(dr**2)))),
        )
    return result


def compare(file: str, duration: float | None, seed: int | None, out: Path) -> dict:
    """Run one paper scenario with ``fused`` added and return the RMS deviations."""
    s = load_scenario(ROOT / "scenarios" / file)
    if "fused" not in s.estimators.names:
        s = replace(s, estimators=replace(s.estimators, passive=(*s.estimators.passive, "fused")))
    s = s.with_overrides(duration=duration, seed=seed)
    run(s, out, record_rrd=False)
    return rms_deviations(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=None)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    base = args.out or Path(tempfile.mkdtemp(prefix="fused_vs_paper_"))
    for file in ("paper_open_loop.toml", "paper_pbvs.toml"):
        rms = compare(file, args.duration, args.seed, base / Path(file).stem)
        best = min((v[0], k) for k, v in rms.items() if k != "fused")
        best_r = min((v[1], k) for k, v in rms.items() if k != "fused")
        print(f"{file}: RMS deviation over the run (outputs in {base / Path(file).stem})")
        for name, (t, r) in rms.items():
            print(f"  {name:22s} {t:8.3f} mm {r:8.4f} deg")
        f_t, f_r = rms["fused"]
        print(
            f"  fused vs best single: translation {best[0] / f_t:.2f}x ({best[1]}), "
            f"rotation {best_r[0] / f_r:.2f}x ({best_r[1]})"
        )


if __name__ == "__main__":
    main()
