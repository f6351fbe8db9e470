"""Real-time factors of the paper's scenarios, against a physics-only baseline.

Run: ``python benchmarks/bench_scenarios.py [--repeats N]``.

For each case it runs the full pipeline (sense → the six estimators and ``fused`` → controller →
step → CSV and Rerun recording; one case without ``fused``, the pipeline the speed targets were
set for) and reports simulated seconds per wall-clock second. The baseline, measured in
the same run, is the twin alone stepping the same duration at zero rates with the camera off:
the ratio says what the rest of the loop costs on top of physics. Targets: ≥ 20× real
time without camera, ≥ 1× with camera, on a 2-core machine; aims 100× and 3×.

The ``acrobot_full`` cases run beside ``acrobot`` ones: ``acrobot + <effect>`` turns on one of
its cable and pulley effects (:data:`EFFECTS`) on the ``acrobot`` profile, the price of each.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.robot.realism import ACROBOT_FULL, CableRealism, PulleyRealism
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import Twin

ROOT = Path(__file__).resolve().parent.parent
_CABLE, _PULLEY = ACROBOT_FULL["cable"], ACROBOT_FULL["pulley"]
EFFECTS: dict[str, tuple[dict, dict]] = {
    "rope stiffness": (
        {k: _CABLE[k] for k in ("rope_stiffness_ratio", "rope_stiffness_std")},
        {},
    ),
    "drum segment": ({"drum_segment": _CABLE["drum_segment"]}, {}),
    "strain damping": ({"strain_damping": True}, {}),
    "viscoelastic rope": (
        {k: _CABLE[k] for k in ("relaxed_ratio", "creep_time", "strain_damping")},
        {},
    ),
    "sheave friction": (
        {k: _CABLE[k] for k in ("drum_segment", "strain_damping")},
        {"sheave_efficiency": _PULLEY["sheave_efficiency"]},
    ),
    "pulley geometry": (
        {},
        {k: _PULLEY[k] for k in ("wrap_diameter", "swivel_tilt_std", "sheave_offset_std")},
    ),
    "swivel friction": ({}, {k: _PULLEY[k] for k in ("swivel_friction", "swivel_bore")}),
}
"""The ``acrobot_full`` cable and pulley effects, one at a time (viscoelastic ropes need the
strain damping, sheave friction also the drum segment: their price is the difference)."""


def physics_only(seconds: float) -> float:
    """Real-time factor of the twin alone (camera off, zero rates)."""
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    with Twin(
        s.model.file,
        deviations=s.truth,
        camera=False,
        align_every=s.model.align_every,
        timestep=s.model.timestep,
    ) as twin:
        twin.reset(s.start_pose)
        ticks = round(seconds * s.model.control_rate)
        t0 = time.perf_counter()
        for _ in range(ticks):
            twin.advance(s.model.control_period, np.zeros(8))
            twin.sense()
        return seconds / (time.perf_counter() - t0)


def scenario_rtf(
    path: Path,
    camera: bool,
    out: Path,
    realism: str = "ideal",
    drop: tuple[str, ...] = (),
    supersample: int = 1,
) -> tuple[float, dict]:
    profile, _, effect = realism.partition(" + ")
    s = load_scenario(path).with_realism(profile).with_overrides(camera=camera)
    if effect:  # one cable or pulley effect of acrobot_full on this profile
        cable, pulley = EFFECTS[effect]
        parts = {"cable": CableRealism(**cable), "pulley": PulleyRealism(**pulley)}
        s = replace(s, realism=replace(s.realism, **parts))
    if supersample > 1:  # pixels that integrate 2 × 2 samples (realism.camera.supersample)
        cam = replace(s.realism.camera, supersample=supersample)
        s = replace(s, realism=replace(s.realism, camera=cam))
    passive = tuple(n for n in s.estimators.passive if n not in drop)
    s = replace(s, estimators=replace(s.estimators, passive=passive))
    result = run(s, out)
    return result.real_time_factor, result.summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="", help="run only the cases whose label has this")
    args = parser.parse_args()
    ol, pb = ROOT / "scenarios/paper_open_loop.toml", ROOT / "scenarios/paper_pbvs.toml"
    blur = load_scenario(pb).realism.camera.blur_subframes
    cases = [
        ("paper_open_loop, no camera, ideal, without fused", ol, False, "ideal", 20.0, 100),
        ("paper_open_loop, no camera, ideal", ol, False, "ideal", 20.0, 100),
        ("paper_open_loop, camera, ideal", ol, True, "ideal", 1.0, 3),
        (f"paper_open_loop, camera, acrobot ({blur} sub-frames)", ol, True, "acrobot", 1.0, 3),
        ("paper_pbvs (control in loop), camera, ideal", pb, True, "ideal", 1.0, 3),
        (f"paper_pbvs, camera, acrobot ({blur} sub-frames)", pb, True, "acrobot", 1.0, 3),
        (f"paper_pbvs, camera, acrobot ({blur} sub-frames, 2×2 px)", pb, True, "acrobot", 1, 3),
        ("paper_open_loop, no camera, acrobot", ol, False, "acrobot", 20.0, 100),
        ("paper_open_loop, no camera, acrobot_full", ol, False, "acrobot_full", 20.0, 100),
        *(
            (f"paper_open_loop, no camera, acrobot + {e}", ol, False, f"acrobot + {e}", 20.0, 100)
            for e in EFFECTS
        ),
        (f"paper_pbvs, camera, acrobot_full ({blur} sub-frames)", pb, True, "acrobot_full", 1, 3),
    ]
    base = statistics.median(physics_only(10.0) for _ in range(args.repeats))
    print(f"cdpr-twin scenario benchmark — median of {args.repeats} runs, outputs written")
    print(f"baseline: twin physics alone (camera off) {base:.1f}× real time\n")
    print(f"{'case':62s} {'sim [s]':>8s} {'RTF':>7s} {'bar':>5s} {'aim':>5s} {'vs physics':>10s}")
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, path, camera, realism, bar, aim) in enumerate(cases):
            if args.only not in label:
                continue
            rtfs, summary = [], {}
            for k in range(args.repeats):
                drop = ("fused",) if "without fused" in label else ()
                out = Path(tmp) / f"case{i}-{k}"
                ss = 2 if "2×2 px" in label else 1
                rtf, summary = scenario_rtf(path, camera, out, realism, drop, ss)
                rtfs.append(rtf)
            rtf = statistics.median(rtfs)
            print(
                f"{label:62s} {summary['simulated_time_s']:8.2f} {rtf:6.2f}× "
                f"{'PASS' if rtf >= bar else 'FAIL':>5s} {'yes' if rtf >= aim else 'no':>5s} "
                f"{rtf / base:9.2f}×"
            )


if __name__ == "__main__":
    main()
