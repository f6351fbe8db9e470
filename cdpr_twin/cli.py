"""The ``cdpr-twin`` command (also ``python -m cdpr_twin``)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from cdpr_twin import model_cli, se3
from cdpr_twin.cli_campaign import add_campaign_parser

P0 = (0.112, -0.032, 0.301, -12.0, -10.0, 0.0)
"""The paper's start pose ᵇp_p0 [m, deg]."""


def _demo(args: argparse.Namespace) -> int:
    from cdpr_twin.sim import ModelError, SimulationError, Twin
    from cdpr_twin.statics import InfeasibleTensionError
    from cdpr_twin.types import T_TAGPUPIL_TAGVISP

    pose = np.array(args.pose, dtype=float)
    try:
        with Twin(model_path=args.model, tension_noise_std=args.noise, noise_seed=args.seed) as t:
            t.reset(se3.pose_from_vector(pose))
            m, truth = t.sense(), t.physics
            dt, dr = truth.settle_error
            print(
                f"ACROBOT twin settled at [{', '.join(f'{v:g}' for v in pose)}] (m, deg): "
                f"{dt * 1e3:.2e} mm / {np.rad2deg(dr):.2e} deg from the request"
            )
            print("cable   rest length l0 [m]   tension [N]")
            for i, (l0, tau) in enumerate(zip(m.cable_lengths, m.tensions, strict=True), 1):
                print(f"  {i}       {l0:.6f}          {tau:7.3f}")
            visp = T_TAGPUPIL_TAGVISP
            truth_tag = se3.vector_from_pose(truth.T_cam_tag @ visp)
            print("tag pose in the camera, ViSP frame [x y z (m), rx ry rz (deg)]:")
            print("  true     ", np.array2string(truth_tag, precision=4, suppress_small=True))
            if m.tag is None:
                print("  detected  none (tag not in view)")
            else:
                det = se3.vector_from_pose(m.tag.T_cam_tag @ visp)
                e_t, e_r = se3.pose_distance(m.tag.T_cam_tag, truth.T_cam_tag)
                print(
                    "  detected ",
                    np.array2string(det, precision=4, suppress_small=True),
                    f" error {e_t * 1e3:.2f} mm / {np.rad2deg(e_r):.2f} deg",
                )
            print("  paper cp_o0 at p0: [-0.123 -0.101 0.338 168 -8 -179]")
    except (ModelError, SimulationError, InfeasibleTensionError, ValueError) as exc:
        print(f"cdpr-twin demo: error: {exc}", file=sys.stderr)
        return 2
    return 0


class _Progress:
    """A one-line progress bar on stderr (a line per 10 % when stderr is not a terminal)."""

    def __init__(self, label: str, stream=sys.stderr) -> None:
        self.label, self.stream = label, stream
        self.tty = stream.isatty()
        self._last = -1

    def __call__(self, fraction: float, t: float) -> None:
        pct = int(100 * fraction)
        if self.tty:
            if pct != self._last:
                bar = "#" * (pct // 4) + "." * (25 - pct // 4)
                self.stream.write(f"\r{self.label} [{bar}] {pct:3d}%  t = {t:6.2f} s")
                self.stream.flush()
        elif pct // 10 != self._last // 10:
            self.stream.write(f"{self.label}: {pct}% (t = {t:.2f} s)\n")
        self._last = pct

    def done(self) -> None:
        """End the bar's line (if one was drawn)."""
        if self.tty and self._last >= 0:
            self.stream.write("\n")


def _table(summary: dict) -> str:
    """The end-of-run table: deviations of every estimator from ground truth (Fig. 5b/7b)."""
    lines = [
        f"{'estimator':22s} {'max Δt [mm]':>11s} {'at [s]':>7s} {'max Δθ [°]':>10s} "
        f"{'final Δt [mm]':>13s} {'final Δθ [°]':>12s} {'invalid':>7s}"
    ]
    for name, e in summary["estimators"].items():
        mark = " (in loop)" if name == summary["in_loop"] else ""
        lines.append(
            f"{name + mark:22s} {e['max_translation_m'] * 1e3:11.3f} "
            f"{e['max_translation_time_s']:7.2f} {e['max_rotation_deg']:10.3f} "
            f"{e['final_translation_m'] * 1e3:13.3f} {e['final_rotation_deg']:12.3f} "
            f"{e['invalid_updates']:7d}"
        )
    return "\n".join(lines)


def _print_ends(s: dict) -> None:
    """Where the platform ended: vs its goal, at each checkpoint, and the tag error (PBVS)."""
    if s["final_error_vs_goal"] is not None:
        err = s["final_error_vs_goal"]
        print(
            f"platform ended {err['translation_m'] * 1e3:.2f} mm / {err['rotation_deg']:.3f}° "
            f"from its goal {np.round(s['goal_pose'], 4).tolist()}"
        )
    for end in s["segment_ends"]:
        err = end["truth_vs_waypoint"]
        print(
            f"  t = {end['time_s']:5.2f} s: {err['translation_m'] * 1e3:7.2f} mm / "
            f"{err['rotation_deg']:.3f}° from waypoint {np.round(end['waypoint'], 4).tolist()}"
        )
    if "pbvs" in s and s["pbvs"]["final_tag_error"] is not None:
        e = s["pbvs"]["final_tag_error"]
        print(
            f"final tag pose error (detected): {e['translation_m'] * 1e3:.2f} mm / "
            f"{e['rotation_deg']:.3f}°"
        )


def _failure(exc: BaseException, out: Path) -> int:
    """Print a run's failure in one line on stderr; returns the exit code."""
    from cdpr_twin.outputs import OutputDirError, OutputError, Terminated
    from cdpr_twin.scenario import ScenarioError

    if isinstance(exc, ScenarioError | OutputDirError):
        message, code = f"error: {exc}", 2
    elif isinstance(exc, OutputError):
        message = f"cannot write {exc.path}: {exc.cause}; what was written is left *.partial"
        code = 1
    elif isinstance(exc, KeyboardInterrupt):
        how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        try:  # this run's summary, or an earlier run's (stopped before it wrote anything)
            ours = json.loads((out / "summary.json").read_text())["status"] == how
        except (OSError, ValueError, KeyError, TypeError):
            ours = False
        message = (
            f'{how}; partial outputs (flushed, marked "{how}") in {out}'
            if ours
            else f"{how} before any output was written"
        )
    else:
        message = f"the run failed: {exc} (outputs up to the failure are in {out})"
        code = 1
    print(f"cdpr-twin: {message}", file=sys.stderr)
    return code


def _run(args: argparse.Namespace) -> int:
    from cdpr_twin.cli_tools import live_url
    from cdpr_twin.outputs import OutputDirError, OutputError, sigterm_raises
    from cdpr_twin.runner import run
    from cdpr_twin.scenario import ScenarioError, load_scenario
    from cdpr_twin.sim import SimulationError

    try:
        if args.spawn and args.connect is not None:
            raise ValueError("give --spawn (a new viewer) or --connect ADDR, not both")
        connect = None if args.connect is None else live_url(args.connect)
        scenario = load_scenario(args.scenario).with_overrides(
            seed=args.seed,
            in_loop=args.in_loop,
            duration=args.duration,
            camera=False if args.no_camera else None,
        )
        if args.realism is not None:
            scenario = scenario.with_realism(args.realism)
    except (ScenarioError, ValueError) as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    out = args.out if args.out is not None else Path("runs") / scenario.name
    progress = _Progress(scenario.name)
    try:
        with sigterm_raises():
            result = run(scenario, out, progress=progress, spawn=args.spawn, connect=connect)
    except (ScenarioError, OutputDirError, OutputError, SimulationError, ValueError,
            KeyboardInterrupt) as exc:  # fmt: skip
        progress.done()
        return _failure(exc, out)
    progress.done()
    s = result.summary
    print(
        f"{scenario.name}: {s['status']} after {s['simulated_time_s']:.2f} s simulated in "
        f"{result.wall_time:.1f} s ({result.real_time_factor:.1f}× real time)"
    )
    print(_table(s))
    _print_ends(s)
    print(f"outputs: {out}/recording.rrd, timeseries.csv, summary.json")
    for fault in s.get("faults", ()):
        print(f"fault at t = {fault['time_s']:.3f} s: {fault['kind']} ({fault['detail']})")
    return 3 if str(s["status"]).startswith("fault:") else 0


def _reproduce(args: argparse.Namespace) -> int:
    from cdpr_twin.study import reproduce

    if args.workers is not None and args.workers < 1:
        print("cdpr-twin: error: --workers must be ≥ 1", file=sys.stderr)
        return 2
    failed = []

    def progress(done: int, total: int, record: dict) -> None:
        mark = "ok" if record["ok"] else "FAILED"
        if not record["ok"]:
            failed.append(record)
        print(f"[{done:3d}/{total}] {record['name']}: {mark} ({record['status']})", file=sys.stderr)

    try:
        from cdpr_twin.realism import RUN_SOURCES

        rep = reproduce(
            args.out,
            args.workers,
            args.runs_scale,
            args.duration,
            progress,
            decompose=RUN_SOURCES if args.decompose else (),
            other_goal=args.other_goal,
            scenarios=model_cli.robot_scenarios(args.robot),
        )
    except ValueError as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cdpr-twin: interrupted; finished runs are in {args.out}/runs", file=sys.stderr)
        return 130
    print(
        f"{rep['runs']['ok']}/{rep['runs']['total']} runs in {rep['wall_time_s'] / 60:.1f} min;"
        f" report: {args.out}/report.md"
    )
    for f in rep["findings"]:
        print(f"  [{f['verdict']:>9s}] {f['finding']}: {f['twin']}")
    for r in failed:
        print(f"failed: {r['name']}: {r['status']}", file=sys.stderr)
    return 0 if not failed else 1


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cdpr-twin`` command."""
    args = _parser().parse_args(argv)
    return args.func(args)


def _parser() -> argparse.ArgumentParser:
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
    demo.add_argument("--model", default="acrobot", help="robot name or MJCF scene file")
    demo.add_argument("--noise", type=float, default=0.24, help="tension noise std [N]")
    demo.add_argument("--seed", type=int, default=0, help="sensor noise seed")
    demo.set_defaults(func=_demo)
    runp = sub.add_parser("run", help="run a scenario headless and write its outputs")
    runp.add_argument(
        "scenario", help="scenario file, or a shipped one's name (cdpr-twin scenarios list)"
    )
    runp.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/<scenario name>)"
    )
    runp.add_argument("--seed", type=int, default=None, help="run seed (sensor noise)")
    runp.add_argument("--in-loop", default=None, help="estimator closing the loop")
    runp.add_argument("--duration", type=float, default=None, help="run length [s]")
    runp.add_argument("--no-camera", action="store_true", help="no rendering (drops 'image')")
    runp.add_argument("--spawn", action="store_true", help="also stream to a live Rerun viewer")
    runp.add_argument(
        "--connect",
        metavar="ADDR",
        default=None,
        help="also stream live to a Rerun gRPC server (port, host:port or rerun+http://…/proxy)",
    )
    runp.add_argument(
        "--realism",
        choices=("ideal", "acrobot"),
        default=None,
        help="realism profile instead of the scenario's (its [realism] overrides are dropped)",
    )
    runp.set_defaults(func=_run)
    _reproduce_parser(sub)
    model_cli.add_parser(sub)  # cdpr-twin model build|workspace
    add_campaign_parser(sub)
    from cdpr_twin import cli_calibrate
    from cdpr_twin.cli_tools import add_parsers

    add_parsers(sub)
    cli_calibrate.add_parser(sub)  # cdpr-twin calibrate
    return parser


def _reproduce_parser(sub) -> None:
    """The ``reproduce`` subcommand's arguments."""
    rep = sub.add_parser("reproduce", help="run the paper's study: runs, figures, report")
    rep.add_argument(
        "--out",
        type=Path,
        default=Path("runs") / "reproduce",
        help="output directory (default: runs/reproduce)",
    )
    rep.add_argument("--workers", type=int, default=None, help="parallel runs (default: cores)")
    rep.add_argument(
        "--runs-scale",
        type=float,
        default=1.0,
        help="scale the repetition counts (10 open-loop, 5 PBVS per estimator)",
    )
    rep.add_argument(
        "--duration", type=float, default=None, help="cap every run's duration [s] (quick checks)"
    )
    rep.add_argument(
        "--decompose",
        action="store_true",
        help="repeat the repeatability runs with each per-run source of variation off",
    )
    rep.add_argument(
        "--other-goal",
        choices=("nominal", "taught"),
        default=None,
        help="also run PBVS (control in the loop) with this goal",
    )
    rep.add_argument("--robot", choices=model_cli.STUDY_ROBOTS, default="acrobot", help="robot")
    rep.set_defaults(func=_reproduce)


if __name__ == "__main__":
    sys.exit(main())
