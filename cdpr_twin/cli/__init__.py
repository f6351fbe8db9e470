"""The ``cdpr-twin`` command (also ``python -m cdpr_twin``)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from cdpr_twin.cli import demo as cli_demo
from cdpr_twin.cli import model as model_cli
from cdpr_twin.cli.campaign import add_campaign_parser
from cdpr_twin.files.transaction import out_path
from cdpr_twin.robot.realism import PROFILES
from cdpr_twin.run.interrupts import closed_stdout

TRACEBACK_HELP = "on an unexpected error (e.g. a plugin's bug), also print its traceback"
REPRODUCE_DOC = (  # `reproduce --help`: what the study writes, and what it removes
    "Run the paper's study into --out: study.json (first), runs/<run>/, runs.json, fig*.png, "
    "report.json, report.md (last). The directory is locked as a run's: a second writer is "
    "refused (exit 2). Before any run starts, an earlier study's report.md, report.json, "
    "runs.json, figures (and their *.partial), runs under runs/ are removed (give another --out "
    "to keep them); such files where no study was are refused (exit 2). Each file is written "
    "as <name>.partial, then renamed. Ctrl-C/SIGTERM stops "
    "the workers (exit 130/143), keeping the finished runs and study.json, without a report. "
    "Exit 0 done, 1 a run or a write failed, 2 bad options or --out in use."
)


class _Progress:
    """A one-line progress bar on stderr (a line per 10 % when stderr is not a terminal)."""

    def __init__(self, label: str, stream=None) -> None:
        self.label = label
        self.stream = sys.stderr if stream is None else stream  # now: not the import's
        self.tty = self.stream.isatty()
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
        e, seen = s["pbvs"]["final_tag_error"], s["pbvs"]["final_tag_error"].get("detected_at_s")
        stale = seen is not None and seen < s["simulated_time_s"] - 1e-6
        print(
            f"{'last' if stale else 'final'} tag pose error (detected): "
            f"{e['translation_m'] * 1e3:.2f} mm / {e['rotation_deg']:.3f}°"
            + (f" at t = {seen:.2f} s; the tag was not seen after it" if stale else "")
        )


def _failure(exc: BaseException, out: Path, show_traceback: bool, since: float) -> int:
    """Print a run's failure (a plugin's bug too) in one line; ``since``: the command's start."""
    from cdpr_twin.files.transaction import OutputDirError, OutputError, Terminated
    from cdpr_twin.scenario.loading import ScenarioError

    if isinstance(exc, ScenarioError | OutputDirError):
        message, code = f"error: {exc}", 2
    elif isinstance(exc, OutputError):
        message = f"cannot write {exc.path}: {exc.cause}; what was written is left *.partial"
        code = 1
    elif isinstance(exc, KeyboardInterrupt):
        how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        status = _status(out, since)  # what the run saved: stopped, ended as it came, nothing
        message = f"{how} before this run saved any output in {out}"
        if status == how:
            message = f'{how}; partial outputs (flushed, marked "{how}") in {out}'
        elif status and not status.startswith("failed"):
            message = f"{how} as the run ended ({status}): its outputs in {out} are complete"
    else:
        kept = _status(out, since).startswith("failed")
        where = f"its outputs, up to the failure, are in {out}" if kept else "nothing was written"
        what, hint = _unexpected(exc, show_traceback)
        message, code = f"the run failed: {what}; {where}{hint}", 1
    print(f"cdpr-twin: {message}", file=sys.stderr)
    return code


def _status(out: Path, since: float = 0.0) -> str:
    """The status in ``out``'s ``summary.json`` written since ``since`` (this run's), or ``""``."""
    try:
        if (out / "summary.json").stat().st_mtime < since:
            return ""  # an earlier run's: this one stopped before it claimed the directory
        return str(json.loads((out / "summary.json").read_text())["status"])
    except (OSError, ValueError, KeyError, TypeError):
        return ""


def _unexpected(exc: BaseException, show_traceback: bool) -> tuple[str, str]:
    """An unexpected exception in one line, and a hint: ``--traceback`` prints the traceback."""
    if show_traceback:
        import traceback

        traceback.print_exc()
    hint = "" if show_traceback else " (--traceback prints where it was raised)"
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}", hint


def _run(args: argparse.Namespace) -> int:
    from cdpr_twin.cli.tools import live_url, run_notes
    from cdpr_twin.run.interrupts import sigterm_raises
    from cdpr_twin.run.runner import run
    from cdpr_twin.scenario.loading import ScenarioError, load_scenario

    try:
        if args.spawn and args.connect is not None:
            raise ValueError("give --spawn (a new viewer) or --connect ADDR, not both")
        connect = None if args.connect is None else live_url(args.connect)
        camera = False if args.no_camera else None
        scenario = load_scenario(args.scenario).with_overrides(
            seed=args.seed, in_loop=args.in_loop, duration=args.duration, camera=camera
        )
        if args.realism is not None:
            scenario = scenario.with_realism(args.realism)
    except (ScenarioError, ValueError) as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    out = args.out if args.out is not None else Path("runs") / scenario.name
    for note in run_notes(scenario, args.spawn):
        print(f"cdpr-twin: note: {note}", file=sys.stderr)
    progress, since = _Progress(scenario.name), time.time()
    try:
        with sigterm_raises():
            result = run(scenario, out, progress=progress, spawn=args.spawn, connect=connect)
    except (Exception, KeyboardInterrupt) as exc:  # a plugin's bug too: one line, not a trace
        progress.done()
        return _failure(exc, out, args.traceback, since)
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
    from cdpr_twin import study
    from cdpr_twin.robot.realism import RUN_SOURCES
    from cdpr_twin.run.interrupts import sigterm_raises

    count, failed = [0, 0], []  # runs finished, planned

    def progress(n: int, total: int, record: dict) -> None:
        count[0] = n
        if not record["ok"]:
            failed.append(record)
        mark = "ok" if record["ok"] else "FAILED"
        print(f"[{n:3d}/{total}] {record['name']}: {mark} ({record['status']})", file=sys.stderr)

    try:
        with sigterm_raises():
            try:  # every option and every run's scenario, before anything runs or is touched
                workers = study.check_workers(args.workers)
                specs = study.study_runs(
                    args.runs_scale,
                    args.duration,
                    model_cli.robot_scenarios(args.robot),
                    decompose=RUN_SOURCES if args.decompose else (),
                    other_goal=args.other_goal,
                )
            except ValueError as exc:  # a ScenarioError too
                print(f"cdpr-twin: error: {exc}", file=sys.stderr)
                return 2
            count[1] = len(specs)
            rep = study.reproduce_runs(args.out, specs, workers, progress)
    except (Exception, KeyboardInterrupt) as exc:
        return _study_failure(exc, args, (count[0], count[1]))
    print(
        f"{rep['runs']['ok']}/{rep['runs']['total']} runs in {rep['wall_time_s'] / 60:.1f} min;"
        f" report: {args.out}/report.md"
    )
    for f in rep["findings"]:
        print(f"  [{f['verdict']:>9s}] {f['finding']}: {f['twin']}")
    for r in failed:
        print(f"failed: {r['name']}: {r['status']}", file=sys.stderr)
    return 0 if not failed else 1


def _study_failure(exc: BaseException, args: argparse.Namespace, finished: tuple[int, int]) -> int:
    """Print why ``reproduce`` stopped (``finished``: runs done, of) in one line; the exit code."""
    from cdpr_twin.files.transaction import OutputDirError, OutputError, Terminated

    out, (n, total) = args.out, finished
    stopped = "" if n == total else "the runs under way were stopped, "
    left = f"{n} of {total} runs had finished (in {out}/runs); no report was written"
    if not total:  # stopped while checking the options: nothing was touched
        left = f"nothing was written in {out}"
    if isinstance(exc, OutputDirError):
        message, code = f"error: {exc}", 2
    elif isinstance(exc, OutputError):
        message = f"cannot write {exc.path}: {exc.cause}; it is left *.partial and {left}"
        code = 1
    elif isinstance(exc, KeyboardInterrupt):
        how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        message = f"{how}; {stopped}{left} (run reproduce again for one)"
    else:
        what, hint = _unexpected(exc, args.traceback)
        message, code = f"reproduce failed: {what}; {left}{hint}", 1
    print(f"cdpr-twin: {message}", file=sys.stderr)
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cdpr-twin`` command."""
    for stream in (sys.stdout, sys.stderr):  # an ASCII terminal gets ° and × escaped, not a crash
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    args = _parser().parse_args(argv)
    try:
        code = args.func(args)
        sys.stdout.flush()  # a reader gone (`| head`) shows here, not at the interpreter's exit
        return code
    except BrokenPipeError as exc:
        return closed_stdout(exc)
    except (SystemExit, KeyboardInterrupt) as exc:  # a plugin's exit; a stop while starting
        from cdpr_twin.files.transaction import Terminated  # (the commands return their exit codes)

        if isinstance(exc, SystemExit):
            why, code = f"error: sys.exit({exc.code!r}) called", 1
        else:
            why, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        print(f"cdpr-twin {args.command}: {why}", file=sys.stderr)
        return code


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cdpr-twin", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    cli_demo.add_parser(sub)  # cdpr-twin demo
    runp = sub.add_parser("run", help="run a scenario headless and write its outputs")
    runp.add_argument(
        "scenario", help="scenario file, or a shipped one's name (cdpr-twin scenarios list)"
    )
    out_help = "output directory (default: runs/<scenario name>)"
    runp.add_argument("--out", type=out_path, default=None, help=out_help)
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
        choices=PROFILES,
        default=None,
        help="realism profile instead of the scenario's (its [realism] overrides are dropped)",
    )
    runp.add_argument("--traceback", action="store_true", help=TRACEBACK_HELP)
    runp.set_defaults(func=_run)
    _reproduce_parser(sub)
    model_cli.add_parser(sub)  # cdpr-twin model build|workspace
    add_campaign_parser(sub)
    from cdpr_twin.cli import calibrate as cli_calibrate
    from cdpr_twin.cli.tools import add_parsers

    add_parsers(sub)
    cli_calibrate.add_parser(sub)  # cdpr-twin calibrate
    return parser


def _reproduce_parser(sub) -> None:
    """The ``reproduce`` subcommand's arguments."""
    rep = sub.add_parser(
        "reproduce",
        help="run the paper's study: runs, figures, report",
        description=REPRODUCE_DOC,
    )
    rep.add_argument(
        "--out",
        type=out_path,
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
    rep.add_argument("--traceback", action="store_true", help=TRACEBACK_HELP)
    rep.set_defaults(func=_reproduce)


if __name__ == "__main__":
    sys.exit(main())
