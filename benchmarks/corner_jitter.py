"""Frame-to-frame jitter of the detected tag corners with the platform held still.

Run: ``python benchmarks/corner_jitter.py [--frames 200] [--pose p1] [--seed 0]``.

The paper's PBVS scenario is built with each camera variant, started at the pose (p1: the tag
large and centred, 0.09 m away, as the PBVS goal has it; p0: the start, 0.36 m away), and the
winches held (zero cable rates). After ``--settle`` control periods (the platform comes to rest
on its cables) the camera is read ``--frames`` times, one control period apart, and the four
detected corners are kept. Reported per variant [px]:

- ``std``: the std over the frames of each of the 8 corner coordinates, as an RMS over them;
- ``diff``: the std of consecutive frames' differences / √2, the same for white noise and blind
  to a slow drift of the platform;
- ``max``: the largest of the 8 coordinates' stds;
- ``bias``: the RMS over the 8 coordinates of the mean detected corner less the true one (the
  true pose projected with the true intrinsics and lens): what stays the same in every frame;
- ``still``: the platform's own motion over the frames (std of its true position, µm): the
  corners' jitter is the camera's only when this is far below a pixel's footprint
  (1 px ≈ 0.2 mm at 0.09 m).

Variants: ``acrobot``; ``acrobot_full``; ``acrobot_full`` without the pixels' fixed pattern
(``prnu_std = dsnu_e = 0``); ``acrobot_full`` with the camera's JPEG encoder at its default
quality 85. The run seed changes the pixel noise, the truth seed the robot (and its pattern).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

import cdpr_twin.sim  # noqa: F401  (defaults MUJOCO_GL=egl before mujoco is imported)
from cdpr_twin.math import se3
from cdpr_twin.run.runner import prepare
from cdpr_twin.scenario.loading import Scenario, load_scenario
from cdpr_twin.sim import imaging
from cdpr_twin.types import Command
from cdpr_twin.vision import detection as vision

ROOT = Path(__file__).resolve().parent.parent
POSES = {"p0": [0.112, -0.032, 0.301, -12.0, -10.0, 0.0], "p1": [0.284, -0.197, 0.08, 0, 0, 0]}


def variants() -> dict[str, Scenario]:
    """The scenarios measured, by name."""
    base = load_scenario(ROOT / "scenarios" / "paper_pbvs.toml")
    full = base.with_realism("acrobot_full")
    optics = full.realism.optics

    def with_optics(**fields: Any) -> Scenario:
        realism = replace(full.realism, optics=replace(optics, **fields))
        return replace(full, realism=realism)

    return {
        "acrobot": base.with_realism("acrobot"),
        "acrobot_full": full,
        "acrobot_full, no fixed pattern": with_optics(prnu_std=0.0, dsnu_e=0.0),
        "acrobot_full, JPEG 85": with_optics(jpeg_quality=85),
    }


def _true_corners(setup) -> np.ndarray:
    """The tag's corners as the true camera sees them now (true intrinsics and lens). (4, 2)."""
    camera, physics = setup.sensors.camera, setup.physics
    K = camera.true_intrinsics
    obj = vision.tag_corners_object(setup.nominal.tag_size)
    T = physics.T_cam_tag
    p = obj @ T[:3, :3].T + T[:3, 3]
    xy = p[:, :2] / p[:, 2:3]
    lens = camera.realism.distortion
    if any(lens):
        xy = imaging.distort_normalized(xy, lens)
    return np.column_stack([K.fx * xy[:, 0] + K.cx, K.fy * xy[:, 1] + K.cy])


def measure(s: Scenario, pose: str, frames: int, settle: int, seed: int) -> dict[str, float]:
    """The corners' jitter, bias and the platform's motion over ``frames`` still frames."""
    s = replace(s, seed=seed)
    setup = prepare(s)
    try:
        T0 = se3.pose_from_vector(np.array(POSES[pose], dtype=float))
        setup.physics.reset(T0)
        setup.sensors.home(T0)
        period, physics = s.model.control_period, setup.physics
        hold = np.zeros(physics.n_cables)
        corners, truth, positions = [], [], []
        for k in range(settle + frames):
            physics.advance(period, hold)
            m = setup.sensors.read(Command(hold, np.zeros(6)))
            if k < settle:
                continue
            if m.tag is None:
                raise RuntimeError(f"{s.realism.profile}: no tag detected at frame {k}")
            corners.append(np.asarray(m.tag.corners, dtype=float).ravel())
            truth.append(_true_corners(setup).ravel())
            positions.append(physics.T_base_platform[:3, 3].copy())
        c, t = np.array(corners), np.array(truth)
        # the frame delivered at a read was exposed latency_ticks reads before: pair it with
        # the truth of then (the platform is still, so this only matters while it settles)
        d = s.realism.camera.latency_ticks
        if d:
            c, t = c[d:], t[:-d]
        return {
            "std": float(np.sqrt(np.mean(c.std(axis=0, ddof=1) ** 2))),
            "diff": float(np.sqrt(np.mean(np.diff(c, axis=0).var(axis=0, ddof=1) / 2.0))),
            "max": float(c.std(axis=0, ddof=1).max()),
            "bias": float(np.sqrt(np.mean((c.mean(axis=0) - t.mean(axis=0)) ** 2))),
            "still": float(1e6 * np.sqrt(np.sum(np.array(positions).var(axis=0, ddof=1)))),
        }
    finally:
        setup.close()


def main() -> None:
    """Print each variant's jitter."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--settle", type=int, default=25)
    parser.add_argument("--pose", choices=sorted(POSES), default="p1")
    parser.add_argument("--seed", type=int, default=0, help="the run seed")
    args = parser.parse_args()
    print(f"pose {args.pose}, {args.frames} frames after {args.settle} settling periods")
    print(f"CPU: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    head = f"{'variant':34s} {'std':>7s} {'diff':>7s} {'max':>7s} {'bias':>7s} {'still':>8s}"
    print(head + "   (px; still: µm)")
    for name, s in variants().items():
        t0 = time.perf_counter()
        r = measure(s, args.pose, args.frames, args.settle, args.seed)
        print(
            f"{name:34s} {r['std']:7.4f} {r['diff']:7.4f} {r['max']:7.4f} {r['bias']:7.3f} "
            f"{r['still']:8.3f}   ({time.perf_counter() - t0:.0f} s)"
        )


if __name__ == "__main__":
    main()
