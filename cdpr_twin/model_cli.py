"""The ``cdpr-twin model`` subcommands: build a robot's MJCF, map its wrench-feasible workspace.

``cdpr-twin model build models/<robot>/robot.toml`` writes ``models/<robot>/<robot>.xml`` and
``scene.xml`` (through ``mujoco.MjSpec``, :mod:`cdpr_twin.sim.generate`);
``cdpr-twin model workspace models/<robot>/robot.toml`` samples the wrench-feasible workspace
(:mod:`cdpr_twin.workspace`) and draws it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

STUDY_ROBOTS = ("acrobot", "cogiro")
"""Robots ``cdpr-twin reproduce --robot`` knows: their (open-loop, PBVS) scenario files."""


def robot_scenarios(robot: str) -> tuple[Path, Path]:
    """The (open-loop, PBVS) scenarios of a robot's study (``reproduce --robot``)."""
    from cdpr_twin import MODELS_DIR

    prefix = "paper" if robot == "acrobot" else robot
    d = MODELS_DIR.parent / "scenarios"
    return d / f"{prefix}_open_loop.toml", d / f"{prefix}_pbvs.toml"


def _build(args: argparse.Namespace) -> int:
    from cdpr_twin.robot import RobotError
    from cdpr_twin.sim.generate import build_files

    try:
        paths = build_files(args.description, args.out)
    except (RobotError, ValueError) as exc:  # a bad description, an infeasible home pose
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    for p in paths:
        print(f"wrote {p}")
    return 0


def _workspace(args: argparse.Namespace) -> int:
    from cdpr_twin.robot import RobotError, load_robot
    from cdpr_twin.workspace import draw_workspace, geometry_of, sample_workspace

    try:
        robot = load_robot(args.description)
    except RobotError as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    ws = sample_workspace(geometry_of(robot), spacing=args.spacing)
    out = args.out or Path(args.description).parent / "workspace.png"
    draw_workspace(ws, out, title=robot.name)
    print(
        f"{ws.feasible.sum()} of {ws.feasible.size} grid points wrench-feasible "
        f"({100 * ws.feasible.mean():.1f} %, spacing {ws.spacing:g} m, tensions "
        f"{ws.tension_range[0]:g}…{ws.tension_range[1]:g} N); figure: {out}"
    )
    return 0


def add_parser(sub) -> None:
    """Register ``model build`` and ``model workspace`` on the main parser's subparsers."""
    model = sub.add_parser("model", help="robot descriptions: build MJCF, map the workspace")
    msub = model.add_subparsers(dest="model_command", required=True)
    build = msub.add_parser("build", help="write <robot>.xml and scene.xml from robot.toml")
    build.add_argument("description", type=Path, help="models/<robot>/robot.toml")
    build.add_argument("--out", type=Path, default=None, help="directory (default: beside it)")
    build.set_defaults(func=_build)
    ws = msub.add_parser("workspace", help="sample and draw the wrench-feasible workspace")
    ws.add_argument("description", type=Path, help="models/<robot>/robot.toml")
    ws.add_argument("--spacing", type=float, default=0.05, help="grid spacing [m]")
    ws.add_argument("--out", type=Path, default=None, help="figure (default: beside it)")
    ws.set_defaults(func=_workspace)
