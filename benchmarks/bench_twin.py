"""Benchmark of the ACROBOT twin: physics step cost, Python overhead, camera sensing, align_every.

Measures, in one run (each timing is the median of several repeats, the robot reset to the
paper's pose p1 before every repeat so that cable lengths never run away):

(a) µs per physics step of bare ``mujoco.mj_step(model, data)`` called in a Python loop on the
    twin's own compiled model (``twin.model``, ``twin.data`` after ``twin.reset(p1)``, constant
    ctrl = winch rates of 1e-4 m/s);
(b) µs per physics step of native ``mujoco.mj_step(model, data, nstep=N)`` on the same model;
(c) µs per physics step of ``Twin.advance(duration, rates)`` (same constant rates) for
    ``align_every`` in (1, 5, 10, 20, 40), with ratios to (a) and (b): the cost of the
    swivel/stiffness refresh done from Python every ``align_every`` steps;
(d) ms per ``Twin.sense()`` with the camera on (render + AprilTag detection), and its parts;
(e) the speed/accuracy trade-off of ``align_every``: after a 2 s run from p1 at the winch rates
    of a 1 cm/s vertical platform twist (A · [0, 0, 0.01, 0, 0, 0], A the nominal base-frame
    pulley Jacobian at p1), the largest difference of the tendon lengths (``twin.cable_lengths``),
    platform pose and tensions from the ``align_every=1`` run.
(f) µs per physics step (align_every = 40) for ACROBOT and CoGiRo, massless and sagging cables.

Run from the repository root (about 6 s on a 2-core machine; well under 2 min):

    /work/venv/bin/python benchmarks/bench_twin.py [--repeats 7] [--steps 4000]

Offscreen rendering uses EGL unless ``MUJOCO_GL`` is already set.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np

from cdpr_twin import MODELS_DIR
from cdpr_twin.math.kinematics import jacobian
from cdpr_twin.math.se3 import pose_distance, pose_from_vector
from cdpr_twin.sim import Physics, build_model
from cdpr_twin.sim.sag import SaggingPhysics
from cdpr_twin.sim.twin import Twin

P1 = pose_from_vector([0.284, -0.197, 0.08, 0.0, 0.0, 0.0])
ALIGN_EVERY = (1, 5, 10, 20, 40)
SMALL_RATE = 1e-4  # m/s: pays out 0.4 mm over a 4000-step run, the platform barely moves
MOVE_TIME = 2.0  # s
MOVE_TWIST = np.array([0.0, 0.0, 0.01, 0.0, 0.0, 0.0])  # 1 cm/s up, base frame


def median_time(run: Callable[[], object], setup: Callable[[], object], repeats: int) -> float:
    """Median wall time [s] of ``run()`` over ``repeats`` runs, ``setup()`` before each."""
    setup()
    run()  # warm-up (caches, lazy allocations)
    times = []
    for _ in range(repeats):
        setup()
        t0 = time.perf_counter()
        run()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def make_twin(align_every: int = 10, camera: bool = False) -> Twin:
    return Twin(camera=camera, tension_noise_std=0.0, align_every=align_every)


def bench_bare(twin: Twin, n: int, repeats: int) -> tuple[float, float]:
    """(a) and (b): µs per bare mj_step, Python loop and native nstep."""
    model, data = twin.model, twin.data
    if model.nu != twin.physics.n_cables:
        raise RuntimeError(f"expected only winch actuators, the model has {model.nu}")

    def setup() -> None:
        twin.reset(P1)
        data.ctrl[:] = SMALL_RATE  # every actuator is a winch

    def python_loop() -> None:
        step = mujoco.mj_step
        for _ in range(n):
            step(model, data)

    def native() -> None:
        mujoco.mj_step(model, data, nstep=n)

    loop_us = median_time(python_loop, setup, repeats) / n * 1e6
    native_us = median_time(native, setup, repeats) / n * 1e6
    return loop_us, native_us


def bench_advance(twin: Twin, n: int, repeats: int) -> float:
    """(c): µs per physics step of Twin.advance."""
    rates = np.full(twin.physics.n_cables, SMALL_RATE)
    duration = n * twin.timestep
    return (
        median_time(lambda: twin.advance(duration, rates), lambda: twin.reset(P1), repeats)
        / n
        * 1e6
    )


ROBOTS = {  # robot: (scene, a pose inside its workspace, cable mass per metre [kg/m])
    "acrobot": (MODELS_DIR / "acrobot" / "scene.xml", P1, 0.0024),
    "cogiro": (
        MODELS_DIR / "cogiro" / "scene.xml",
        pose_from_vector([2.0, -1.5, 1.0, 0, 0, 0]),
        0.064,
    ),
}


def bench_robots(n: int, repeats: int) -> None:
    """(f): µs per physics step (align_every = 40) for each robot, massless and sagging cables."""
    print(f"{'(f) robot':<12}{'cables':>8}{'µs/step massless':>20}{'µs/step sagging':>20}")
    for name, (scene, pose, rho) in ROBOTS.items():
        cost = []
        for physics in (
            Physics(build_model(scene), 40),
            SaggingPhysics(build_model(scene), 40, linear_density=rho),
        ):
            rates = np.full(physics.n_cables, SMALL_RATE)
            run = lambda p=physics, r=rates: p.advance(n * p.timestep, r)  # noqa: E731
            reset = lambda p=physics, T=pose: p.reset(T)  # noqa: E731
            cost.append(median_time(run, reset, repeats) / n * 1e6)
        print(f"{name:<12}{physics.n_cables:>8}{cost[0]:>20.2f}{cost[1]:>20.2f}")


def bench_sense(repeats: int) -> dict[str, float | bool]:
    """(d): ms per sense() with the camera, and its parts."""
    with make_twin(camera=True) as twin:
        twin.reset(P1)
        noop = lambda: None  # noqa: E731
        detected = twin.sense().tag is not None
        out: dict[str, float | bool] = {
            "sense": median_time(twin.sense, noop, repeats) * 1e3,
            "render": median_time(twin.render, noop, repeats) * 1e3,
            "no_render": median_time(lambda: twin.sense(render=False), noop, repeats) * 1e3,
            "detected": detected,
        }
    return out


def move_run(twin: Twin, rates: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(e): one 2 s run from p1; returns (µs/step, lengths, pose, tensions) at its end."""
    twin.reset(P1)
    n = round(MOVE_TIME / twin.timestep)
    t0 = time.perf_counter()
    twin.advance(MOVE_TIME, rates)
    us = (time.perf_counter() - t0) / n * 1e6
    return us, twin.cable_lengths.copy(), twin.T_base_platform, twin.tensions.copy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=7, help="repeats per timing (median)")
    parser.add_argument("--steps", type=int, default=4000, help="physics steps per timed run")
    args = parser.parse_args()
    n, repeats = args.steps, args.repeats
    t_start = time.perf_counter()

    twins = {k: make_twin(align_every=k) for k in ALIGN_EVERY}
    dt_ms = twins[1].timestep * 1e3

    loop_us, native_us = bench_bare(twins[10], n, repeats)
    advance_us = {k: bench_advance(twins[k], n, repeats) for k in ALIGN_EVERY}
    sense = bench_sense(max(repeats, 15))

    A = jacobian(twins[1].nominal_geometry, P1, "base", "pulley")
    move_rates = A @ MOVE_TWIST
    runs = {k: move_run(twins[k], move_rates) for k in ALIGN_EVERY}
    ref = runs[1]

    mujoco_version = mujoco.__version__
    print(
        f"ACROBOT twin benchmark — MuJoCo {mujoco_version}, timestep {dt_ms:g} ms, "
        f"{n} steps per timed run, median of {repeats} runs, reset to p1 before each"
    )
    print()
    print(f"{'case':<40}{'µs/step':>10}{'twin/bare-loop':>16}{'twin/bare-native':>18}")
    print("-" * 84)
    print(f"{'(a) mj_step in a Python loop (bare)':<40}{loop_us:>10.2f}{'—':>16}{'—':>18}")
    print(f"{'(b) mj_step(nstep=N), native (bare)':<40}{native_us:>10.2f}{'—':>16}{'—':>18}")
    for k in ALIGN_EVERY:
        us = advance_us[k]
        label = f"(c) Twin.advance, align_every={k}"
        print(f"{label:<40}{us:>10.2f}{us / loop_us:>15.2f}x{us / native_us:>17.2f}x")
    print()
    print(
        f"(d) Twin.sense() with camera: {sense['sense']:.1f} ms per call "
        f"(render {sense['render']:.1f} ms, sense without render {sense['no_render']:.3f} ms; "
        f"tag detected at p1: {sense['detected']})"
    )
    print()
    print(
        f"(e) align_every trade-off: {MOVE_TIME:g} s from p1 at the rates of a 1 cm/s vertical "
        f"twist (|rate| ≤ {np.abs(move_rates).max() * 1e3:.2f} mm/s), "
        "differences from align_every=1 at the end"
    )
    header = (
        f"{'align_every':>11}{'µs/step':>10}{'max|ΔL| [nm]':>15}"
        f"{'Δposition [nm]':>16}{'Δrotation [µrad]':>18}{'max|Δτ| [mN]':>14}"
    )
    print(header)
    print("-" * len(header))
    for k in ALIGN_EVERY:
        us, lengths, T, tau = runs[k]
        d_len = np.abs(lengths - ref[1]).max() * 1e9
        d_pos, d_rot = pose_distance(ref[2], T)
        d_tau = np.abs(tau - ref[3]).max() * 1e3
        print(
            f"{k:>11}{us:>10.2f}{d_len:>15.3f}{d_pos * 1e9:>16.3f}"
            f"{d_rot * 1e6:>18.4f}{d_tau:>14.3f}"
        )
    z_moved = (runs[1][2][2, 3] - P1[2, 3]) * 1e3
    print(f"(platform rose {z_moved:.2f} mm in the align_every=1 run)")
    print()
    bench_robots(args.steps, args.repeats)
    print()
    print(f"total benchmark time {time.perf_counter() - t_start:.1f} s")


if __name__ == "__main__":
    main()
