"""What each cable and pulley effect does to the four model-based estimators, and its price.

Run: ``python benchmarks/rope_effects.py [--duration 25] [--only WORD…]`` (the cases whose
label holds a word), or ``--price`` for the physics
alone: the time of a physics step with each effect (the fastest of several interleaved
rounds, which a loaded machine slows least).

The paper's open-loop scenario with the robot's geometry errors off (``[truth]`` stds zero,
its seed kept for the per-robot draws), the camera off and no tension noise, so that the
ideal twin's ``model_elastic_pulley`` matches the truth to numerical precision. Each case turns
on one effect of ``[realism.cable]``/``[realism.pulley]`` (the ``acrobot_full`` magnitudes) on
the ideal profile; the last ones turn them all on, then the whole ``acrobot_full`` profile.
Per estimator it prints the RMS translation error over the run and the final one, at rest at
p0 [mm], and the RMS rotation error [°]; and each case's real-time factor (the price of the
effect; noisy on a shared machine: ``bench_scenarios.py`` measures it).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.robot.realism import ACROBOT_FULL, CableRealism, PulleyRealism
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import build_robot

ROOT = Path(__file__).resolve().parent.parent
MODELS = ("model_simple", "model_elastic", "model_pulley", "model_elastic_pulley")
CABLE, PULLEY = ACROBOT_FULL["cable"], ACROBOT_FULL["pulley"]


def _pick(table: dict, *names: str) -> dict:
    return {n: table[n] for n in names}


CASES: tuple[tuple[str, str, dict, dict], ...] = (
    ("ideal (the paper's model)", "ideal", {}, {}),
    ("rope stiffness", "ideal", _pick(CABLE, "rope_stiffness_ratio", "rope_stiffness_std"), {}),
    ("drum segment", "ideal", _pick(CABLE, "drum_segment"), {}),
    ("strain-rate damping", "ideal", _pick(CABLE, "strain_damping"), {}),
    (
        "viscoelastic rope (+ strain damping)",
        "ideal",
        _pick(CABLE, "relaxed_ratio", "creep_time", "strain_damping"),
        {},
    ),
    (
        "drum segment, strain damping",
        "ideal",
        _pick(CABLE, "drum_segment", "strain_damping"),
        {},
    ),
    (
        "sheave friction (+ drum, strain damping)",
        "ideal",
        _pick(CABLE, "drum_segment", "strain_damping"),
        _pick(PULLEY, "sheave_efficiency"),
    ),
    ("cable diameter in the wrap", "ideal", {}, _pick(PULLEY, "wrap_diameter")),
    (
        "swivel tilt, sheave offset",
        "ideal",
        {},
        _pick(PULLEY, "swivel_tilt_std", "sheave_offset_std"),
    ),
    ("swivel friction", "ideal", {}, _pick(PULLEY, "swivel_friction", "swivel_bore")),
    ("all cable and pulley effects", "ideal", CABLE, PULLEY),
    ("acrobot", "acrobot", {}, {}),
    ("acrobot_full", "acrobot_full", CABLE, PULLEY),
)


def scenario(profile: str, cable: dict, pulley: dict, duration: float):
    """paper_open_loop without geometry errors, camera or tension noise, with these effects."""
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml").with_realism(profile)
    s = s.with_overrides(camera=False, duration=duration)
    if profile == "ideal":
        s = s.without("tension_noise")
    zero = {f: 0.0 for f in vars(s.truth) if f != "seed"}
    realism = replace(s.realism, cable=CableRealism(**cable), pulley=PulleyRealism(**pulley))
    return replace(s, truth=replace(s.truth, **zero), realism=realism)


def price(rounds: int = 7, seconds: float = 1.0) -> None:
    """Print the physics step's time with each effect: ACROBOT at p0, winches swinging."""
    s = load_scenario(ROOT / "scenarios" / "paper_open_loop.toml")
    robots = {}
    for label, profile, cable, pulley in CASES:
        if profile != "ideal":
            continue
        built = build_robot(
            s.model.file,
            s.truth,
            s.model.timestep,
            s.model.align_every,
            cable=CableRealism(**cable),
            pulley=PulleyRealism(**pulley),
        )
        built.physics.reset(s.start_pose)
        robots[label] = built.physics
    best = dict.fromkeys(robots, math.inf)
    ticks = round(seconds / s.model.control_period)
    for _ in range(rounds):
        for label, physics in robots.items():
            t0 = time.perf_counter()
            for k in range(ticks):
                # ±1 mm/s, reversing every 0.2 s: the sheaves stick and slip
                rate = 1e-3 * math.copysign(1.0, math.sin(2 * math.pi * 2.5 * k / 25))
                physics.advance(s.model.control_period, rate * (np.arange(8) % 2 - 0.5))
            best[label] = min(best[label], time.perf_counter() - t0)
    steps = ticks * round(s.model.control_period / s.model.timestep)
    base = best[CASES[0][0]]
    print(f"physics alone, fastest of {rounds} rounds of {seconds:g} s")
    for label, t in best.items():
        print(f"{label:42s} {1e6 * t / steps:6.1f} µs/step  {t / base:5.2f}× the ideal")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=25.0)
    parser.add_argument("--price", action="store_true", help="time the physics step only")
    parser.add_argument(
        "--only", nargs="+", metavar="WORD", help="the cases whose label holds one of these"
    )
    args = parser.parse_args()
    if args.price:
        price()
        return
    head = " ".join(f"{m[6:]:>21s}" for m in MODELS)
    print(f"paper_open_loop, {args.duration:g} s, geometry errors off, camera off")
    print("per estimator: RMS / final translation error [mm], RMS rotation error [°]")
    print(f"{'case':42s} {head} {'RTF':>6s}")
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, profile, cable, pulley) in enumerate(CASES):
            if args.only and not any(word in label for word in args.only):
                continue
            result = run(scenario(profile, cable, pulley, args.duration), Path(tmp) / str(i))
            est = result.summary["estimators"]
            cells = " ".join(
                f"{1e3 * e['rms_translation_m']:6.3f}/{1e3 * e['final_translation_m']:8.2e}"
                f" {e['rms_rotation_deg']:5.3f}"
                for e in (est[m] for m in MODELS)
            )
            print(f"{label:42s} {cells} {result.real_time_factor:5.1f}×", flush=True)


if __name__ == "__main__":
    main()
