"""Waiting for a writer thread that may have died: give up once it stops writing.

Rerun writes a recording in a thread of its own, and its ``flush`` waits without end for a file
writer that died mid-flush (seen on a full disk: the run then hung at its end, deaf to SIGTERM).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from pathlib import Path

STALL_S = 15.0
"""How long the file may stay the same size before the writer is taken for dead [s]."""

ABANDON_S = 10.0
"""How long a failed or stopped run's clean-up waits for Rerun's ``disconnect`` [s]: it writes
what is still buffered, and blocks without end for a writer that died (what was written stays
``*.partial`` either way)."""


class WriterStalledError(RuntimeError):
    """A writer thread stopped writing in the middle of a flush: it is taken for dead."""


def flush_while_writing(
    flush: Callable[[float], None], path: Path, stall_s: float = STALL_S, poll_s: float = 1.0
) -> None:
    """Wait for a writer's flush as long as it keeps writing ``path``.

    Args:
        flush: ``flush(timeout_s)``, raising ``RuntimeError`` ("… timed out …") on a timeout.
        path: the file the writer writes.
        stall_s: give up once the file has not grown for this long [s].
        poll_s: each wait for the flush [s].

    Raises:
        RuntimeError: the writer's own error.
        WriterStalledError: it wrote nothing for ``stall_s``.
    """
    size, since = -1, time.monotonic()
    while True:
        try:
            return flush(poll_s)
        except RuntimeError as exc:
            if "timed out" not in str(exc):
                raise
        with contextlib.suppress(OSError):
            if (grown := path.stat().st_size) != size:
                size, since = grown, time.monotonic()
        if time.monotonic() - since > stall_s:
            raise WriterStalledError(f"its writer wrote nothing for {stall_s:g} s (a full disk?)")


def call_with_deadline(
    fn: Callable[[], object], timeout_s: float, if_late: Callable[[], object] | None = None
) -> bool:
    """Call ``fn`` in a daemon thread and wait at most ``timeout_s`` [s] for it.

    For a library call that can block without end (Rerun's ``disconnect`` flushes a file writer
    that may have died). Its exceptions are swallowed: it is a clean-up.

    Args:
        fn: the call.
        timeout_s: how long to wait for it [s].
        if_late: called when ``fn`` has not returned in time (e.g. to keep an exit hook from
            waiting for it in turn).

    Returns:
        Whether it returned within ``timeout_s`` (if not, it is left running in its thread; for
        Rerun, ``if_late`` unregisters its at-exit shutdown, for the whole process).
    """

    def call() -> None:
        with contextlib.suppress(Exception):
            fn()

    name = f"deadline-{getattr(fn, '__name__', 'call')}"
    thread = threading.Thread(target=call, name=name, daemon=True)
    thread.start()
    thread.join(timeout_s)
    if (late := thread.is_alive()) and if_late is not None:
        if_late()
    return not late
