"""``cdpr-twin campaign``: run a campaign file, with one progress bar across workers."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from cdpr_twin.cli.progress import Progress


class CampaignProgress:
    """Runs done of the total, failed, rate and time left, across every worker.

    A terminal gets a redrawn line (:class:`~cdpr_twin.cli.progress.Progress`); a log gets the
    command's final line only.
    """

    def __init__(self, label: str, stream=None) -> None:
        self.line = Progress(label, "runs", stream)
        self.failed = 0

    def __call__(self, done: int, total: int, row: dict) -> None:
        """Account one finished run and redraw."""
        self.failed += 0 if row["ok"] else 1
        self.line.update(done, total, f"{self.failed} failed" if self.failed else "")

    def done(self) -> None:
        """End the line."""
        self.line.done()


def campaign_command(args: argparse.Namespace) -> int:
    """Run ``args.campaign``; exit 0 (all ran), 1 (some failed), 2 (bad input), 130/143."""
    from cdpr_twin.campaign import (
        CampaignError,
        ExecutorError,
        load_campaign,
        run_campaign,
    )
    from cdpr_twin.campaign.executor import check_address
    from cdpr_twin.campaign.report import write_report
    from cdpr_twin.campaign.spec import shortened
    from cdpr_twin.files.transaction import OutputDirError, OutputError, Terminated
    from cdpr_twin.run.interrupts import sigterm_raises

    if args.workers is not None and args.workers < 1:
        print("cdpr-twin: error: --workers must be ≥ 1", file=sys.stderr)
        return 2
    try:
        campaign = load_campaign(args.campaign)
        if args.duration is not None:
            campaign = shortened(campaign, args.duration)
    except CampaignError as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    out = args.out if args.out is not None else Path("runs") / campaign.name
    progress, since = CampaignProgress(campaign.name), time.time()
    ray = False if args.ray is None else (args.ray or True)
    try:
        if isinstance(ray, str):  # before its directory is made: a wrong address writes nothing
            check_address(ray)
    except ExecutorError as exc:
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    try:
        with sigterm_raises():
            info = run_campaign(campaign, out, args.workers, ray, args.resume, progress)
            report = write_report(out, campaign)
    except (OutputDirError, ExecutorError) as exc:
        progress.done()
        print(f"cdpr-twin: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        progress.done()
        print(f"cdpr-twin: cannot write {exc.path}: {exc.cause}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        progress.done()
        how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
        print(f"cdpr-twin: {how}; {_what_was_kept(out, since)}", file=sys.stderr)
        return code
    progress.done()
    print(
        f"{campaign.name}: {info['ran_now']} runs now, {info['skipped_done']} already done, "
        f"{progress.failed} failed, in {info['wall_time_s'] / 60:.1f} min; "
        f"table: {out}/results.parquet; report: {report}"
    )
    return 1 if progress.failed else 0


def _what_was_kept(out: Path, since: float) -> str:
    """After a stop: what this command recorded (``campaign.json`` written since ``since``)."""
    import json

    from cdpr_twin.campaign.table import PARTS, RESULTS

    rest = "run again with --resume for the rest"
    try:
        if (out / "campaign.json").stat().st_mtime < since:
            raise ValueError  # an earlier campaign's: this one stopped before it ran anything
        ran = json.loads((out / "campaign.json").read_text(encoding="utf-8"))["ran_now"]
    except (OSError, ValueError, KeyError):
        ran = 0
    table = out / RESULTS if (out / RESULTS).exists() else out / PARTS
    if not ran and not any(out.glob(f"{PARTS}/part-*.parquet")):
        return f"no run finished now ({rest})"
    if not ran:
        return f"no run finished now; the runs before are in {table} ({rest}, and the report)"
    return f"{ran} runs finished now and are recorded in {table} ({rest})"


def add_campaign_parser(sub) -> None:
    """The ``campaign`` subcommand."""
    from cdpr_twin.files.transaction import out_path

    cp = sub.add_parser("campaign", help="run a campaign file: many varied runs into one table")
    cp.add_argument(
        "campaign", type=Path, help="campaign file, or a shipped one's name (campaigns list)"
    )
    cp.add_argument("--out", type=out_path, default=None, help="output directory (runs/<name>)")
    cp.add_argument("--workers", type=int, default=None, help="parallel runs (default: cores)")
    cp.add_argument("--resume", action="store_true", help="run only the runs not in the table")
    cp.add_argument(
        "--duration", type=float, default=None, help="cap every run's duration [s] (quick checks)"
    )
    cp.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=None,
        metavar="ADDRESS",
        help="run on Ray: a local cluster, or the cluster at ADDRESS (pip install -e '.[ray]')",
    )
    cp.set_defaults(func=campaign_command)
