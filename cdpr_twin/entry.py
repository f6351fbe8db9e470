"""The entry point of ``cdpr-twin`` and ``python -m cdpr_twin``: stops first, then the CLI.

Importing the command (numpy, MuJoCo, Rerun, OpenCV…) takes a second or more. A Ctrl-C or
SIGTERM in that time used to print a ``KeyboardInterrupt`` traceback from whichever import it
landed in. Here, with the standard library only, SIGINT and SIGTERM are handled before anything
heavy is imported (:func:`cdpr_twin.run.interrupts.handle_stops`): a stop at any time, start-up
included, exits 130 (Ctrl-C) or 143 (SIGTERM) with one line on stderr and no traceback. The
first stop decides; once the command has its exit code every later signal is ignored while the
interpreter exits.

Rerun's own logger (Rust's) prints its warnings and errors, coloured, before the command's one
line (e.g. a recording on a full disk). It reads ``RUST_LOG`` once, when Rerun is imported; the
command sets it to ``off`` unless the user set it (``RUST_LOG=warn cdpr-twin run …`` shows
Rerun's log again).
"""

from __future__ import annotations

import os
import sys

RERUN_LOG_DEFAULT = "off"
"""``RUST_LOG`` when the user set none: Rerun's log is quiet (its failures reach us as errors)."""


def main() -> int:
    """Run the ``cdpr-twin`` command; its exit code."""
    from cdpr_twin.files.transaction import Terminated
    from cdpr_twin.run.interrupts import handle_stops, interruption, settle

    handle_stops()
    os.environ.setdefault("RUST_LOG", RERUN_LOG_DEFAULT)  # before Rerun's first import
    try:
        from cdpr_twin import cli

        return cli.main()
    except (KeyboardInterrupt, SystemError) as exc:  # (SystemError: a stop in compiled code)
        if (stop := interruption(exc)) is None:
            raise
        how, code = ("terminated", 143) if isinstance(stop, Terminated) else ("interrupted", 130)
        print(f"cdpr-twin: {how} while starting", file=sys.stderr)
        return code
    finally:
        settle()
