"""Tidying the run directories of runs that died mid-way (a stopped campaign's or study's)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

from cdpr_twin.outputs import LOCK_NAME, OUTPUT_NAMES, _guard, _owner, _stale, partial_of


def sweep_abandoned(parent: Path, wait: float = 0.0) -> list[Path]:
    """Tidy the run directories under ``parent`` whose run died (its lock's owner is gone).

    A campaign or study stopped ends its workers mid-run (SIGTERM, then SIGKILL): their run
    directories keep the lock and the ``*.partial`` files the run had begun. Those go, and the
    directory too when nothing else is left in it; a live run's directory is not touched.

    Args:
        parent: the directory of the run directories.
        wait: up to this long [s], wait for the owners on this host to end (Ray's shutdown
            does not wait for its workers).

    Returns:
        The directories tidied.
    """
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline and any(
        _owner(lock) and not _stale(_owner(lock)) for lock in Path(parent).glob(f"*/{LOCK_NAME}")
    ):
        time.sleep(0.1)
    tidied = []
    for lock in sorted(Path(parent).glob(f"*/{LOCK_NAME}")):
        directory = lock.parent
        with contextlib.suppress(OSError), _guard(directory):
            if not _stale(_owner(lock)):
                continue
            for name in OUTPUT_NAMES:
                partial_of(directory / name).unlink(missing_ok=True)
            lock.unlink()
            tidied.append(directory)
        with contextlib.suppress(OSError):
            directory.rmdir()  # (only if empty)
    return tidied
