"""The ``cdpr-twin`` command (also ``python -m cdpr_twin``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from cdpr_twin import DEFAULT_SCENE, se3

P0 = (0.112, -0.032, 0.301, -12.0, -10.0, 0.0)
"""The paper's start pose ᵇp_p0 [m, deg]."""


def _demo(args: argparse.Namespace) -> int:
    from cdpr_twin.sim import ModelError, Twin
    from cdpr_twin.statics import InfeasibleTensionError
    from cdpr_twin.vision import T_TAGPUPIL_TAGVISP

    pose = np.array(args.pose, dtype=float)
    try:
        with Twin(model_path=args.model, tension_noise_std=args.noise, noise_seed=args.seed) as t:
            t.reset(se3.pose_from_vector(pose))
            m = t.sense()
            dt, dr = t.settle_error
            print(
                f"ACROBOT twin settled at [{', '.join(f'{v:g}' for v in pose)}] (m, deg): "
                f"{dt * 1e3:.2e} mm / {np.rad2deg(dr):.2e} deg from the request"
            )
            print("cable   rest length l0 [m]   tension [N]")
            for i, (l0, tau) in enumerate(zip(m.cable_lengths, m.tensions, strict=True), 1):
                print(f"  {i}       {l0:.6f}          {tau:7.3f}")
            visp = T_TAGPUPIL_TAGVISP
            truth = se3.vector_from_pose(t.T_cam_tag @ visp)
            print("tag pose in the camera, ViSP frame [x y z (m), rx ry rz (deg)]:")
            print("  true     ", np.array2string(truth, precision=4, suppress_small=True))
            if m.tag is None:
                print("  detected  none (tag not in view)")
            else:
                det = se3.vector_from_pose(m.tag.T_cam_tag @ visp)
                e_t, e_r = se3.pose_distance(m.tag.T_cam_tag, t.T_cam_tag)
                print(
                    "  detected ",
                    np.array2string(det, precision=4, suppress_small=True),
                    f" error {e_t * 1e3:.2f} mm / {np.rad2deg(e_r):.2f} deg",
                )
            print("  paper cp_o0 at p0: [-0.123 -0.101 0.338 168 -8 -179]")
    except (ModelError, InfeasibleTensionError, ValueError) as exc:
        print(f"cdpr-twin demo: error: {exc}", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cdpr-twin`` command."""
    parser = argparse.ArgumentParser(prog="cdpr-twin", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="settle the twin at a pose, print tensions and the tag")
    demo.add_argument(
        "--pose",
        nargs=6,
        type=float,
        default=P0,
        metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
        help="platform pose [m, m, m, deg, deg, deg] (default: the paper's p0)",
    )
    demo.add_argument("--model", type=Path, default=DEFAULT_SCENE, help="MJCF scene file")
    demo.add_argument("--noise", type=float, default=0.24, help="tension noise std [N]")
    demo.add_argument("--seed", type=int, default=0, help="sensor noise seed")
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
