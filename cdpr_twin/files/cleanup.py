"""Tidying the run directories of runs that died mid-way (a stopped campaign's or study's)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

from cdpr_twin.files.transaction import LOCK_NAME, OutputDir, OutputDirError, OutputError


def sweep_abandoned(parent: Path, wait: float = 0.0) -> list[Path]:
    """Tidy the run directories under ``parent`` whose run died (its lock's owner is gone).

    A campaign or study stopped ends its workers mid-run (SIGTERM, then SIGKILL): their run
    directories keep the lock and the ``*.partial`` files the run had begun. Each is claimed
    as the next run there would claim it (:class:`~cdpr_twin.files.transaction.OutputDir`: the dead
    run's lock taken over, its files removed), released, and removed when nothing else is
    left in it; a live run's directory is not touched.

    Args:
        parent: the directory of the run directories.
        wait: up to this long [s], wait for the owners on this host to end (Ray's shutdown
            does not wait for its workers).

    Returns:
        The directories tidied.
    """
    deadline = time.monotonic() + wait
    tidied = []
    for lock in sorted(Path(parent).glob(f"*/{LOCK_NAME}")):
        if _take(OutputDir(lock.parent), deadline):
            tidied.append(lock.parent)
            with contextlib.suppress(OSError):
                lock.parent.rmdir()  # (only if empty)
    return tidied


def _take(run: OutputDir, deadline: float) -> bool:
    """Claim and release ``run``'s directory, retrying while its owner lives until ``deadline``."""
    while True:
        try:
            run.claim()
        except OutputDirError:  # its run is alive (on Ray, maybe still ending)
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.1)
            continue
        except OutputError:  # a file that cannot be removed: left as it is
            return False
        run.release()
        return True
