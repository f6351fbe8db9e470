"""The ``demo`` subcommand of ``cdpr-twin``: the twin settled at a pose, its tensions and tag."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from cdpr_twin.math import se3

P0 = (0.112, -0.032, 0.301, -12.0, -10.0, 0.0)
"""The paper's start pose ᵇp_p0 [m, deg]."""


def _demo(args: argparse.Namespace) -> int:
    """Settle the twin at ``--pose`` and print what it senses (exit 2: a bad option or model)."""
    from cdpr_twin.math.statics import InfeasibleTensionError
    from cdpr_twin.sim import ModelError, SimulationError, Twin
    from cdpr_twin.types import T_TAGPUPIL_TAGVISP

    pose = np.array(args.pose, dtype=float)
    try:
        if args.seed < 0:  # as run's --seed (numpy's words did not name the option)
            raise ValueError(f"--seed must be an integer ≥ 0, got {args.seed}")
        if not 0 <= args.noise < np.inf:
            raise ValueError(f"--noise must be a tension noise std ≥ 0 N, got {args.noise}")
        with Twin(model_path=args.model, tension_noise_std=args.noise, noise_seed=args.seed) as t:
            t.reset(se3.pose_from_vector(pose))
            m, truth = t.sense(), t.physics
            dt, dr = truth.settle_error
            print(
                f"{Path(args.model).stem} twin settled at [{', '.join(f'{v:g}' for v in pose)}] "
                f"(m, deg): {dt * 1e3:.2e} mm / {np.rad2deg(dr):.2e} deg from the request"
            )
            print("cable   rest length l0 [m]   tension [N]")
            for i, (l0, tau) in enumerate(zip(m.cable_lengths, m.tensions, strict=True), 1):
                print(f"  {i}       {l0:.6f}          {tau:7.3f}")
            truth_tag = se3.vector_from_pose(truth.T_cam_tag @ T_TAGPUPIL_TAGVISP)
            print("tag pose in the camera, ViSP frame [x y z (m), rx ry rz (deg)]:")
            print("  true     ", np.array2string(truth_tag, precision=4, suppress_small=True))
            if m.tag is None:
                print("  detected  none (tag not in view)")
            else:
                det = se3.vector_from_pose(m.tag.T_cam_tag @ T_TAGPUPIL_TAGVISP)
                e_t, e_r = se3.pose_distance(m.tag.T_cam_tag, truth.T_cam_tag)
                text = np.array2string(det, precision=4, suppress_small=True)
                print("  detected ", text, f" error {e_t * 1e3:.2f} mm / {np.rad2deg(e_r):.2f} deg")
            if args.model == "acrobot" and pose.tolist() == list(P0):  # the paper's own view
                print("  paper cp_o0 at p0: [-0.123 -0.101 0.338 168 -8 -179]")
    except (ModelError, SimulationError, InfeasibleTensionError, ValueError) as exc:
        print(f"cdpr-twin demo: error: {exc}", file=sys.stderr)
        return 2
    return 0


def add_parser(sub) -> None:
    """The ``demo`` subcommand's arguments."""
    demo = sub.add_parser("demo", help="settle the twin at a pose, print tensions and the tag")
    demo.add_argument(
        "--pose",
        nargs=6,
        type=float,
        default=P0,
        metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
        help="platform pose [m, m, m, deg×3] (default: ACROBOT's p0; give one for other robots)",
    )
    demo.add_argument("--model", default="acrobot", help="robot name or MJCF scene file")
    demo.add_argument("--noise", type=float, default=0.24, help="tension noise std [N]")
    demo.add_argument("--seed", type=int, default=0, help="sensor noise seed")
    demo.set_defaults(func=_demo)
