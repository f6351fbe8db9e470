"""The ``cdpr-twin model`` subcommands: build a robot's MJCF, map its wrench-feasible workspace.

``cdpr-twin model build models/<robot>/robot.toml`` writes ``models/<robot>/<robot>.xml`` and
``scene.xml`` (through ``mujoco.MjSpec``, :mod:`cdpr_twin.sim.mjcf_from_robot`);
``cdpr-twin model workspace models/<robot>/robot.toml`` samples the wrench-feasible workspace
(:mod:`cdpr_twin.math.workspace`) and draws it.

Both check every input first (a bad ``--out`` or ``--spacing`` is a one-line error, exit 2)
and write whole files only: ``<name>.partial`` first, renamed once complete (``model build``:
both files complete before either is renamed); a failed write (disk full) is a one-line error,
exit 1, that leaves the earlier files as they were.
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


def _out_dir(description: Path, out: Path | None) -> Path:
    """``model build``'s output directory, checked usable (not created).

    Raises:
        ValueError: it is not a directory, or cannot be written (the fix in the message).
    """
    from cdpr_twin.files.paths import path_kind, unwritable

    out = Path(description).parent if out is None else Path(out)
    kind = path_kind(out, ValueError)
    if kind not in (None, "dir"):
        raise ValueError(f"--out {out}: exists and is not a directory; give a directory")
    if kind == "dir" and (why := unwritable(out)):
        raise ValueError(f"--out {out}: cannot write there ({why}); give another")
    return out


def _named(ref: Path) -> tuple[Path, bool]:
    """A description's file, and whether it was given as a shipped robot's name.

    Raises:
        ValueError: a bare name that is neither a file nor a shipped robot (the choices said).
    """
    from cdpr_twin import resources

    try:
        path = resources.robot_description(ref)
    except resources.ResourceError as exc:
        raise ValueError(str(exc)) from None
    return path, path != ref


def _build(args: argparse.Namespace) -> int:
    from cdpr_twin.files.transaction import OutputError
    from cdpr_twin.robot.description import RobotError
    from cdpr_twin.sim.mjcf_from_robot import build_files

    try:
        description, named = _named(args.description)
        # a shipped robot builds into ./<name>/, never into the installed package
        out = _out_dir(description, args.out or (Path(args.description.name) if named else None))
        paths = build_files(description, out)  # both whole, or neither renamed
    except (RobotError, ValueError) as exc:  # a bad description or --out, an infeasible home
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the directory cannot be reached or created
        where = args.out or Path(args.description).parent
        print(
            f"cdpr-twin: error: --out {where}: cannot create it: {exc.strerror or exc}; give "
            "another directory",
            file=sys.stderr,
        )
        return 2
    except OutputError as exc:
        print(
            f"cdpr-twin: error: cannot write {exc.path}: {exc.cause}; no half-written file is "
            f"left ({exc.fix('give another --out')})",
            file=sys.stderr,
        )
        return 1
    for p in paths:
        print(f"wrote {p}")
    return 0


def _workspace(args: argparse.Namespace) -> int:
    from cdpr_twin.cli.plots import missing_plots

    if message := missing_plots("model workspace"):
        print(message, file=sys.stderr)
        return 2
    from cdpr_twin.files.transaction import OutputError
    from cdpr_twin.math.workspace import geometry_of, sample_workspace, spacing_problem
    from cdpr_twin.robot.description import RobotError, load_robot

    try:  # every input checked before the (long) sampling
        description, named = _named(args.description)
        beside = Path(f"{args.description.name}_workspace.png") if named else None
        out = args.out or beside or description.parent / "workspace.png"
        robot = load_robot(description)
        geom = geometry_of(robot)
        if problem := spacing_problem(geom, args.spacing):
            raise ValueError(f"--spacing {args.spacing:g}: {problem}")
        try:
            figure_format(out)
        except ValueError as exc:  # its message starts with the path
            raise ValueError(f"--out {exc}") from None
    except (RobotError, ValueError) as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    from cdpr_twin.cli.progress import Progress

    line = Progress(f"workspace of {robot.name}", "points")
    try:
        ws = sample_workspace(geom, spacing=args.spacing, progress=line.update)
    finally:
        line.done()
    try:
        draw_workspace(ws, out, title=robot.name)
    except OutputError as exc:
        print(
            f"cdpr-twin: error: cannot write {exc.path}: {exc.cause}; an earlier figure is kept "
            f"({exc.fix('give another --out')})",
            file=sys.stderr,
        )
        return 1
    print(
        f"{ws.feasible.sum()} of {ws.feasible.size} grid points wrench-feasible "
        f"({100 * ws.feasible.mean():.1f} %, spacing {ws.spacing:g} m, tensions "
        f"{ws.tension_range[0]:g}…{ws.tension_range[1]:g} N); figure: {out}"
    )
    return 0


def figure_format(path: str | Path) -> str:
    """The format a figure at ``path`` is written in (its extension), checked writable.

    Raises:
        ValueError: naming the path, the problem and the fix: a directory, a missing or
            unwritable parent directory, a path the OS refuses to look at (a name too long),
            or an extension matplotlib cannot write.
    """
    import shutil

    import matplotlib
    from matplotlib.backend_bases import FigureCanvasBase

    from cdpr_twin.files.paths import path_kind, unwritable

    path = Path(path)
    kinds = FigureCanvasBase.get_supported_filetypes()
    fmt = path.suffix[1:].lower()
    if path_kind(path, ValueError) == "dir":
        raise ValueError(f"{path} is a directory; give a file name, e.g. {path / 'workspace.png'}")
    if (parent := path_kind(path.parent, ValueError)) != "dir":
        missing = "is not a directory" if parent else "does not exist"
        raise ValueError(f"{path}: {path.parent} {missing}; give a file in an existing directory")
    if why := unwritable(path.parent):  # found before the sampling, not after
        raise ValueError(f"{path}: cannot write in {path.parent} ({why}); give another directory")
    if fmt not in kinds:
        raise ValueError(
            f"{path}: cannot write a figure as {path.suffix or 'a file without an extension'}; "
            f"end the name in one of {', '.join(f'.{k}' for k in sorted(kinds))} (e.g. .png)"
        )
    if fmt == "pgf" and shutil.which(matplotlib.rcParams["pgf.texsystem"]) is None:
        tex = matplotlib.rcParams["pgf.texsystem"]
        raise ValueError(f"{path}: .pgf needs {tex}, not found; end the name in .png, .pdf or .svg")
    return fmt


def draw_workspace(ws, path: str | Path, title: str = "") -> Path:
    """Draw a sampled workspace: feasible points in 3D, and the feasible area per height.

    The figure is written whole or not at all: as ``<name>.partial``, ``fsync``'ed, then
    renamed (an existing file is replaced); on failure the partial file is removed.

    Args:
        ws: the sampled :class:`~cdpr_twin.math.workspace.Workspace`.
        path: the figure to write; its extension is the format (``.png``, ``.pdf``, ``.svg``…).
        title: figure title (the robot's name).

    Returns:
        The path written.

    Raises:
        ValueError: ``path`` cannot hold a figure (:func:`figure_format`).
        cdpr_twin.files.transaction.OutputError: writing it failed (disk full…), naming it and the
            cause.
    """
    from matplotlib.figure import Figure

    fmt = figure_format(path)

    fig = Figure(figsize=(10, 4.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    pts = ws.points()
    ax.scatter(*pts.T, s=4, c=pts[:, 2], cmap="viridis", depthshade=False)
    ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
    ax.set_title(f"{title}: wrench-feasible positions (level platform)", fontsize=9)
    area = ws.feasible.sum(axis=(0, 1)) * ws.spacing**2
    fit = ws.inside.sum(axis=(0, 1)) * ws.spacing**2
    a2 = fig.add_subplot(1, 2, 2)
    a2.plot(fit, ws.zs, "--", color="grey", label="platform inside the frame")
    a2.plot(area, ws.zs, label="wrench-feasible")
    a2.set(xlabel="area [m²]", ylabel="z [m]")
    lo, hi = ws.tension_range
    a2.set_title(f"{lo:g} N ≤ τ ≤ {hi:g} N, grid {ws.spacing:g} m", fontsize=9)
    a2.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, Path(path), fmt)
    return Path(path)


def _save(fig, path: Path, fmt: str) -> None:
    """``fig`` into ``path`` through ``<path>.partial``: never a half-written figure."""
    from cdpr_twin.files.transaction import save_figure

    save_figure(fig, path, keep_partial=False, dpi=110, format=fmt)


def add_parser(sub) -> None:
    """Register ``model build`` and ``model workspace`` on the main parser's subparsers."""
    model = sub.add_parser("model", help="robot descriptions: build MJCF, map the workspace")
    msub = model.add_subparsers(dest="model_command", required=True)
    build = msub.add_parser("build", help="write <robot>.xml and scene.xml from robot.toml")
    build.add_argument(
        "description", type=Path, help="a robot.toml, or a shipped robot's name (robots list)"
    )
    build.add_argument(
        "--out", type=Path, default=None, help="directory (default: beside it; a name: ./NAME)"
    )
    build.set_defaults(func=_build)
    ws = msub.add_parser("workspace", help="sample and draw the wrench-feasible workspace")
    ws.add_argument(
        "description", type=Path, help="a robot.toml, or a shipped robot's name (robots list)"
    )
    ws.add_argument(
        "--spacing", type=float, default=0.05, help="grid step [m] (default 0.05; ≤ 1e6 points)"
    )
    ws.add_argument(
        "--out",
        type=Path,
        default=None,
        help="figure, .png/.pdf/.svg… (default: beside it; a name: ./NAME_workspace.png)",
    )
    ws.set_defaults(func=_workspace)
