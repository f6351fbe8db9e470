"""``cdpr-twin calibrate SCENARIO``: self-calibrate the scenario's robot in the twin.

Bad input (options, the scenario, a start pose the robot cannot be homed at) is refused, exit
2, before any directory is made or process started. A calibration that fails before writing
anything leaves no output directory it created itself.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from cdpr_twin.cli.progress import Progress, duration

MAX_POSES, MAX_FRAMES = 10_000, 1_000
"""Upper bounds of ``--poses`` (40× the default: ≈ 40 min) and ``--frames``: beyond them a typo
would run for days, its memory growing, before saying anything."""


def _check_options(args: argparse.Namespace) -> None:
    """The numbers on the command line, checked before anything runs.

    Raises:
        ScenarioError: naming the option and what it must be.
    """
    from cdpr_twin.scenario.loading import ScenarioError

    if not 12 <= args.poses <= MAX_POSES:  # 12: the unknowns need them
        raise ScenarioError(f"--poses must be within 12…{MAX_POSES}, got {args.poses}")
    if not 1 <= args.frames <= MAX_FRAMES:
        raise ScenarioError(
            f"--frames (readings averaged per pose) must be within 1…{MAX_FRAMES}, "
            f"got {args.frames}"
        )
    if args.workers < 1:
        raise ScenarioError(f"--workers must be ≥ 1, got {args.workers}")


def _missing(out: Path) -> list[Path]:
    """``out`` and its ancestors that do not exist yet (what claiming it creates), deepest first.

    Raises:
        cdpr_twin.files.transaction.OutputDirError: ``out`` cannot be looked at (e.g. a name too
            long).
    """
    from cdpr_twin.files.paths import path_kind
    from cdpr_twin.files.transaction import OutputDirError

    made = []
    while path_kind(out, OutputDirError) is None and out != out.parent:
        made.append(out)
        out = out.parent
    return made


def _remove_empty(made: list[Path]) -> None:
    """Remove the directories this command created, deepest first, while they are empty."""
    for path in made:
        try:
            path.rmdir()
        except OSError:  # not empty (a partial file, another writer's file) or gone: keep it
            return


def _calibrate(args: argparse.Namespace) -> int:
    from cdpr_twin.calibrate.acquire import check
    from cdpr_twin.calibrate.output import MARKER, NAMES
    from cdpr_twin.files.paths import path_kind
    from cdpr_twin.files.transaction import OutputDir, OutputDirError, OutputError, others
    from cdpr_twin.scenario.loading import ScenarioError, load_scenario

    started, made = time.perf_counter(), []
    try:  # everything checked before a directory is made or a process started
        _check_options(args)
        s = load_scenario(args.scenario).with_overrides(seed=args.seed)
        source = s.model.nominal or s.model.file.parent / "robot.toml"
        if path_kind(source, ScenarioError) != "file":
            raise ScenarioError(
                f"{s.source}: model: no robot description {source} beside the model file; "
                'give one with [model] nominal = "robot.toml"'
            )
        check(s)  # the robot builds, its start pose can be homed at (as `cdpr-twin run` checks)
        out = Path(args.out or Path("runs") / f"{s.name}_calibration")
        if source.resolve() in {(out / name).resolve() for name in NAMES}:
            raise ScenarioError(  # before: cleared first, then "robot description not found"
                f"--out {out}: this calibration would replace {source}, the description it "
                "starts from (model.nominal); give another --out, or copy that file elsewhere"
            )
        made = _missing(out)
        # a run's, campaign's or study's directory is refused (its files are not ours to clear)
        owner = OutputDir(
            out,
            outputs=(),
            foreign=others("calibration"),
            partials=NAMES,
            owned=NAMES,
            marker=MARKER,
            inputs=(s.source, source, s.model.file),
        )
        owner.claim()  # refuses a directory another calibration is writing
    except (ScenarioError, OutputDirError, OutputError) as exc:
        _remove_empty(made)
        print(f"cdpr-twin calibrate: error: {exc}", file=sys.stderr)
        return 2
    code = 1
    try:
        code = _guarded(args, s, source, out, started)
    finally:
        owner.release()
        if code != 0:  # nothing written: no empty directory of ours is left behind
            _remove_empty(made)
    return code


def _guarded(args, s, source: Path, out: Path, started: float) -> int:
    """:func:`_solve_and_write`, its errors turned into one line and an exit code."""
    from cdpr_twin.calibrate.solver import CalibrationError
    from cdpr_twin.files.transaction import OutputError, Terminated
    from cdpr_twin.run.interrupts import sigterm_raises
    from cdpr_twin.scenario.loading import ScenarioError
    from cdpr_twin.sim import ModelError

    try:
        with sigterm_raises():
            return _solve_and_write(args, s, source, out, started)
    except (ScenarioError, ModelError, CalibrationError) as exc:
        print(f"cdpr-twin calibrate: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        fix = exc.fix("give another --out")
        print(f"cdpr-twin calibrate: error: cannot write {exc}; {fix}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (Terminated): nothing half-written
        term = isinstance(exc, Terminated)
        print(f"cdpr-twin calibrate: {'terminated' if term else 'interrupted'}", file=sys.stderr)
        return 143 if term else 130


def _solve_and_write(args, s, source: Path, out: Path, started: float) -> int:
    """Excite, record, solve; write the description and the report (the long part)."""
    from cdpr_twin.calibrate.output import clear, write
    from cdpr_twin.calibrate.pipeline import calibrate, truth_check, weighting_report
    from cdpr_twin.sim import build_robot

    clear(out)  # an earlier calibration's files go first: none survives a failed one
    line = Progress("calibrate", "segments")

    def progress(stage: str, done: int, total: int) -> None:
        if stage == "recording":
            line.update(done, total, f"{args.poses} poses, {args.workers} workers")
        else:
            line.stage(f"{stage} (recorded in {duration(time.perf_counter() - line.start)})")

    try:
        outcome = calibrate(s, args.poses, args.frames, args.workers, progress=progress)
    finally:
        line.done()
    nominal = build_robot(s.model.file, nominal_path=s.model.nominal).nominal
    cal, rec = outcome.calibration, outcome.recording
    extra = {
        "scenario": str(s.source),
        "robot_seed": s.truth.seed,
        "run_seed": s.seed,
        "poses": rec.obs.n_poses,
        "poses_without_redundancy_left_out": outcome.dropped,
        "tag_seen": int(rec.obs.seen.sum()),
        "timing_s": {
            "excitation": outcome.excitation_s,
            "recording": rec.wall_time,
            "solve": cal.wall_time,
            "total": time.perf_counter() - started,
            "simulated": rec.simulated_time,
        },
        **weighting_report(outcome),
        "check_against_truth": truth_check(outcome, nominal.geometry, nominal.T_base_tag),
    }
    robot, report = write(out, source, cal, extra, rec.drum_radii)
    _print(cal, extra, robot, report)
    return 0


def _print(cal, extra: dict, robot: Path, report: Path) -> None:
    from cdpr_twin.calibrate.solver import GROSS_CHI2

    idn, chk = cal.identifiability, extra["check_against_truth"]
    t = extra["timing_s"]
    print(
        f"calibrated from {extra['poses']} poses, the homed one first (tag seen at "
        f"{extra['tag_seen']}; "
        f"{extra['poses_without_redundancy_left_out']} without a redundant equation left out) in "
        f"{t['total']:.1f} s (recording {t['recording']:.1f} s, solve {t['solve']:.1f} s)"
    )
    print(
        f"fit: cable residual RMS {cal.rms_cable * 1e6:.1f} µm, tag "
        f"{cal.rms_tag[0] * 1e3:.2f} mm / {np.degrees(cal.rms_tag[1]):.2f}°; "
        f"rank {idn.rank} of {idn.n_params} (unseen: {len(idn.null_directions)} directions)"
    )
    vc = extra.get("variance_components")
    if vc:
        n = extra["noise_model"]
        print(
            f"weights: each measurement's noise re-estimated from its residuals over "
            f"{len(vc['rounds'])} solves ({'settled' if vc['settled'] else vc['note']}): cables "
            f"{n['length_std'] * 1e6:.1f} µm, tag {n['tag_lateral_std'] * 1e3:.2f} mm lateral + "
            f"{n['tag_std_per_m'] * 1e3:.2f} mm/m, {np.degrees(n['tag_rotation_std']):.2f}°"
        )
        if vc["tag_views_left_out"]:
            print(
                f"tag views left out as gross errors (χ² > {GROSS_CHI2} after the first solve): "
                f"{len(vc['tag_views_left_out'])}, at poses {vc['tag_views_left_out']}"
            )
    sig = cal.sigma[[i for i, n in enumerate(cal.names) if n.startswith("exit")]]
    print(f"exit points: median 1σ {np.median(sig) * 1e3:.2f} mm per axis")
    if idn.prior_determined:
        print(f"decided by the priors, not the data: {', '.join(idn.prior_determined)}")
    for name in ("nominal", "calibrated"):
        c = chk[name]
        print(
            f"check against the truth, {name}: exit points median {c['exit_error_median_mm']:.2f}"
            f" mm (shape {c['exit_shape_error_median_mm']:.2f} mm), anchors "
            f"{c['anchor_error_median_mm']:.2f} mm"
        )
    print(f"wrote {robot} and {report}")


def add_parser(sub) -> None:
    """Add ``calibrate`` to the command's subparsers."""
    from cdpr_twin.files.transaction import out_path

    p = sub.add_parser(
        "calibrate", help="self-calibrate a scenario's robot; write a calibrated robot.toml"
    )
    p.add_argument("scenario", help="a scenario file, or a shipped scenario's name")
    p.add_argument(
        "--out", type=out_path, help="output directory (default: runs/<name>_calibration)"
    )
    p.add_argument("--poses", type=int, default=240, help="excitation poses (default 240)")
    p.add_argument("--frames", type=int, default=4, help="readings averaged per pose (default 4)")
    p.add_argument("--seed", type=int, help="run seed (sensor noise) instead of the file's")
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="processes recording the tour's segments side by side (default: all cores; the "
        "result does not depend on it)",
    )
    p.set_defaults(func=_calibrate)
