"""Ctrl-C and SIGTERM seen through compiled code and through other libraries.

SIGTERM raises :class:`~cdpr_twin.outputs.Terminated` (and Ctrl-C ``KeyboardInterrupt``) from
the signal handler, wherever the main thread is. Two paths lose what it was:

- inside a numba-compiled function the handler runs when the function hands back, and CPython
  reports the pair as ``SystemError: …returned a result with an exception set``, the interrupt
  as its cause: the run would be recorded as failed where it was stopped;
- a library that checks signals in its own loop (Ray's ``ray.get``/``ray.wait``) re-raises
  the interrupt as a plain ``KeyboardInterrupt``: a SIGTERM would be told as a Ctrl-C.

:func:`interruption` recovers the stop either way (the SIGTERM handler notes its signal), and
:func:`sigterm_raises`, around each command, hands it on as the stop it is.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

from cdpr_twin.outputs import Terminated

_SIGTERM = threading.Event()
"""Set by :func:`sigterm_raises`' handler: a SIGTERM arrived (cleared on entering and leaving
it)."""


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM ``exc`` is, or that surfaced as it; else ``None``.

    A plain ``KeyboardInterrupt`` after a SIGTERM (a library re-raised its
    :class:`~cdpr_twin.outputs.Terminated` as the base class) is a ``Terminated``.
    """
    stop = exc if isinstance(exc, KeyboardInterrupt) else None
    if isinstance(exc, SystemError) and isinstance(exc.__cause__, KeyboardInterrupt):
        stop = exc.__cause__
    if stop is not None and not isinstance(stop, Terminated) and _SIGTERM.is_set():
        return Terminated()
    return stop


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within: SIGTERM raises :class:`~cdpr_twin.outputs.Terminated`; restored on leaving.

    Once: a second SIGTERM is ignored while the outputs are completed. The main thread only.
    A Ctrl-C or SIGTERM that surfaced otherwise (:func:`interruption`) leaves as itself.
    """

    def handler(signum, frame) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _SIGTERM.set()
        raise Terminated()

    _SIGTERM.clear()
    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    except (SystemError, KeyboardInterrupt) as exc:
        if (stop := interruption(exc)) is None or stop is exc:
            raise
        raise stop from None
    finally:
        signal.signal(signal.SIGTERM, previous)
        _SIGTERM.clear()  # a later Ctrl-C, outside this command, is a Ctrl-C


@contextlib.contextmanager
def shielded(escape: bool = False) -> Iterator[None]:
    """Within: SIGINT and SIGTERM are held off, so that the outputs being saved are completed.

    A run completes, renames and commits its files in well under a second; a (second) Ctrl-C
    or SIGTERM during that used to interrupt it, leaving ``*.partial`` files and the lock. A
    signal that came is delivered on leaving, to the handler it was meant for, unless it is of
    the kind of a stop already under way (which absorbs it); also when the body raised (the
    stop came first: it is the one that leaves). SIGKILL still stops it. In another thread
    than the main one (where signals cannot be handled) it does nothing.

    Args:
        escape: a second signal while one is held is not held but handled at once (a body
            that hangs can still be stopped without SIGKILL).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous: dict = {}

    def hold(signum, frame) -> None:
        meant = previous.get(signum)
        if escape and held and callable(meant):
            meant(signum, frame)  # raises (Ctrl-C, Terminated) here, in the body
        held.append(signum)

    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, hold)
        yield
    finally:
        for sig, handler in previous.items():
            if handler is not None:  # (None: a handler installed from C, not restorable)
                signal.signal(sig, handler)
        stopping = sys.exc_info()[1]  # raised in the body, or a stop under way around it
        absorbed = signal.SIGTERM if isinstance(stopping, Terminated) else signal.SIGINT
        for sig in dict.fromkeys(held):  # each kind once, in the order they came
            if not (isinstance(stopping, KeyboardInterrupt) and sig == absorbed):
                signal.raise_signal(sig)  # now, to the handler it was meant for (a worker: exit)


def closed_stdout(exc: BrokenPipeError) -> int:
    """After a ``BrokenPipeError``: if standard output's reader is gone (``cdpr-twin … | head``).

    The rest of the output is dropped without a word (as ``cat`` does); standard output goes to
    ``/dev/null`` so that the interpreter's own flush at exit fails no more. Returns 141, the
    status of a process ended by SIGPIPE (128 + 13). A run's files are complete either way:
    the summary is printed after they are saved. A broken pipe elsewhere (a socket, a plugin's)
    is not standard output's: ``exc`` is raised again.
    """
    import os

    try:
        sys.stdout.flush()
    except BrokenPipeError:
        pass
    else:  # nothing was buffered (``python -u``, PYTHONUNBUFFERED): ask the pipe itself
        if not _reader_gone(sys.stdout):
            raise exc
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 128 + signal.SIGPIPE


def _reader_gone(stream) -> bool:
    """Whether ``stream``'s file is a pipe or socket whose reader has gone (poll: an error)."""
    import select

    try:
        poll = select.poll()
        poll.register(stream.fileno(), select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poll.poll(0))
    except (OSError, ValueError, AttributeError):  # no file descriptor, or a closed one
        return False
