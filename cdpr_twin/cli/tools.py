"""Subcommands ``scenarios``, ``campaigns``, ``robots`` and ``view``; ``--connect``'s address.

- ``cdpr-twin scenarios list`` — the shipped scenarios, with their descriptions;
- ``cdpr-twin scenarios copy NAME DIR`` — a shipped scenario copied into ``DIR`` to start one's
  own (it names its robot, so it runs from anywhere); the copy is written whole or not at all
  (:func:`cdpr_twin.files.transaction.write_whole`), so a failed copy can simply be retried;
- ``cdpr-twin campaigns list|copy`` — the same for the shipped campaigns (they name their
  scenarios by shipped name);
- ``cdpr-twin robots list|copy`` — the shipped robots; a copy holds what the description needs;
- ``cdpr-twin view RUN_DIR`` — the run's ``recording.rrd`` in the Rerun viewer.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path
from urllib.parse import urlsplit

from cdpr_twin import resources
from cdpr_twin.files.transaction import out_path

LIVE_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
"""URL schemes of a Rerun gRPC server (``run --connect``)."""


def live_url(address: str) -> str:
    """A Rerun gRPC server's URL from what ``run --connect`` was given.

    A port (``9876``) or ``host:port`` expands to ``rerun+http://<host>:<port>/proxy``, as the
    ``rerun --connect`` option does; a URL is kept when it names a host, a port and ``/proxy``
    (what the Rerun SDK connects to; it drops another URL's recording without a word).

    Raises:
        ValueError: for anything else, saying what to give.
    """
    if address.isdigit():
        return f"rerun+http://127.0.0.1:{_port(address)}/proxy"
    if address.startswith(LIVE_SCHEMES) and _proxy_url(address):
        return address
    host, _, port = address.rpartition(":")
    if "://" not in address and host and port.isdigit():
        return f"rerun+http://{host}:{_port(port)}/proxy"
    raise ValueError(
        f"--connect {address!r}: give a port, host:port or a URL rerun+http://host:port/proxy"
    )


def _proxy_url(address: str) -> bool:
    """Whether a URL names a host, a port and the path ``/proxy``, and nothing else.

    Raises:
        ValueError: its port is not in 1…65535.
    """
    url = urlsplit(address)
    port = url.netloc.rpartition(":")[2]
    if any(c.isspace() for c in address) or not (url.hostname and port.isdigit()):
        return False
    return url.path == "/proxy" and not (url.query or url.fragment) and bool(_port(port))


def run_notes(scenario, spawn: bool) -> list[str]:
    """What a run will do that its command line may not say.

    A duration rounded to whole control ticks; a viewer that cannot open (``--spawn``).

    Args:
        scenario: the run's scenario (:class:`cdpr_twin.scenario.loading.Scenario`).
        spawn: ``--spawn`` was given.
    """
    notes = []
    period = scenario.model.control_period
    ticks = round(scenario.duration / period)
    if abs(ticks * period - scenario.duration) > 1e-9:
        notes.append(
            f"duration {scenario.duration:g} s runs {ticks} control ticks of {period:g} s, "
            f"{ticks * period:g} s"
        )
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if spawn and sys.platform.startswith("linux") and headless:  # (macOS: no DISPLAY needed)
        notes.append(
            "--spawn: no display (DISPLAY and WAYLAND_DISPLAY unset), so no viewer can open; "
            "the run goes on and writes recording.rrd (open it later with cdpr-twin view, or "
            "stream to a viewer elsewhere with --connect)"
        )
    return notes


def _port(digits: str) -> int:
    """A TCP port number from its digits (1…65535), else a ``ValueError`` saying so."""
    if not 1 <= int(digits) <= 65535:
        raise ValueError(f"--connect: port {digits} is not a TCP port: give one in 1…65535")
    return int(digits)


def viewer_command(run_dir: Path) -> list[str]:
    """The command that opens a run's recording in the Rerun viewer.

    Args:
        run_dir: a run's output directory, or a ``.rrd`` file.

    Raises:
        FileNotFoundError: when there is no recording there, or the path cannot be looked at
            (a name too long): one line saying what to give.
    """
    from cdpr_twin.files.paths import path_kind

    rrd = run_dir if run_dir.suffix == ".rrd" else run_dir / "recording.rrd"
    if path_kind(rrd, FileNotFoundError) != "file":
        raise FileNotFoundError(
            f"{rrd}: no recording; give a run directory written by cdpr-twin run (or a .rrd)"
        )
    return [sys.executable, "-m", "rerun", str(rrd)]  # the rerun-sdk installed beside us


def _view(args: argparse.Namespace) -> int:
    try:
        command = viewer_command(args.run_dir)
    except FileNotFoundError as exc:
        print(f"cdpr-twin view: error: {exc}", file=sys.stderr)
        return 2
    if args.print_command:
        print(shlex.join(command))  # pasted into a shell: a path with spaces stays one word
        return 0
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):  # the viewer would fail with its own multi-line error
        print(
            "cdpr-twin view: error: no display here (DISPLAY and WAYLAND_DISPLAY unset); copy "
            "the recording to a machine with one, or print the command with --print-command",
            file=sys.stderr,
        )
        return 2
    try:
        viewer = subprocess.Popen(command)
    except OSError as exc:
        print(f"cdpr-twin view: error: cannot start the viewer: {exc}", file=sys.stderr)
        return 1
    try:
        return viewer.wait()
    except KeyboardInterrupt:
        viewer.terminate()
        return 130


def _description(path: Path) -> str:
    try:
        return str(tomllib.loads(path.read_text(encoding="utf-8-sig")).get("description", ""))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return "(unreadable)"


def _listed(kind: str) -> list[tuple[str, str]]:
    """The shipped resources of one kind: (name, one line about it)."""
    if kind == "scenarios":
        folder = resources.scenarios_dir()
        return [(n, _description(folder / f"{n}.toml")) for n in resources.scenarios()]
    if kind == "campaigns":
        folder = resources.campaigns_dir()
        return [(n, _description(folder / f"{n}.toml")) for n in resources.campaigns()]
    folder = resources.models_dir()
    return [(n, _robot_line(folder / n / resources.DESCRIPTION_FILE)) for n in resources.robots()]


def _robot_line(path: Path) -> str:
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return "(unreadable)"
    cables = len(data.get("cables", {}).get("exit_points_m", [])) or "?"
    return f"{cables} cables; {path.parent / resources.SCENE_FILE}"


COPIERS = {
    "scenarios": (resources.copy_scenario, "run it: cdpr-twin run {}"),
    "campaigns": (resources.copy_campaign, "run it: cdpr-twin campaign {}"),
    "robots": (resources.copy_robot, "build it: cdpr-twin model build {}"),
}
"""Each kind's copy function, and the command that uses the copy."""


def _shipped(args: argparse.Namespace) -> int:
    kind = args.kind
    if args.action == "list":
        for name, line in _listed(kind):
            print(f"{name:24s} {line}")
        return 0
    from cdpr_twin.files.transaction import OutputError

    copy, then = COPIERS[kind]
    try:
        target = copy(args.name, args.dir)
    except resources.ResourceError as exc:
        print(f"cdpr-twin {kind} copy: error: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:
        print(
            f"cdpr-twin {kind} copy: error: cannot write {exc.path}: {exc.cause}; nothing "
            f"was copied ({exc.fix('copy into another directory')})",
            file=sys.stderr,
        )
        return 1
    print(f"{target} ({then.format(shlex.quote(str(target)))})")
    return 0


def add_parsers(sub) -> None:
    """Add the ``scenarios``, ``campaigns``, ``robots`` and ``view`` subcommands."""
    for kind, one, helps in (
        ("scenarios", "scenario", "list the shipped scenarios, or copy one to edit"),
        ("campaigns", "campaign", "list the shipped campaigns, or copy one to edit"),
        ("robots", "robot", "list the shipped robots, or copy one's description to edit"),
    ):
        sc = sub.add_parser(kind, help=helps)
        actions = sc.add_subparsers(dest="action", required=True)
        actions.add_parser("list", help=f"the shipped {kind}")
        copy = actions.add_parser("copy", help=f"copy a shipped {one} into a directory")
        copy.add_argument("name", help=f"a shipped {one} (see: cdpr-twin {kind} list)")
        copy.add_argument(
            "dir", type=out_path, help="directory to copy it into (created if needed)"
        )
        sc.set_defaults(func=_shipped, kind=kind)
    view = sub.add_parser("view", help="open a run's recording in the Rerun viewer")
    view.add_argument("run_dir", type=Path, help="a run's output directory (or a .rrd file)")
    view.add_argument(
        "--print-command", action="store_true", help="print the viewer command, do not start it"
    )
    view.set_defaults(func=_view)
