"""Ctrl-C and SIGTERM seen through compiled code and through other libraries.

SIGTERM raises :class:`~cdpr_twin.files.transaction.Terminated` (and Ctrl-C ``KeyboardInterrupt``)
from
the signal handler, wherever the main thread is. Two paths lose what it was:

- inside a numba-compiled function the handler runs when the function hands back, and CPython
  reports the pair as ``SystemError: …returned a result with an exception set``, the interrupt
  as its cause: the run would be recorded as failed where it was stopped;
- a library that checks signals in its own loop (Ray's ``ray.get``/``ray.wait``) re-raises
  the interrupt as a plain ``KeyboardInterrupt``: a SIGTERM would be told as a Ctrl-C.

The first stop decides: once a Ctrl-C or SIGTERM has begun to stop a command, any later one,
of either kind, is ignored while its outputs are completed, so that the exit code (130 or 143)
agrees with the status its files record (``"interrupted"`` or ``"terminated"``). SIGKILL still
ends it.

:func:`interruption` recovers the stop either way (the handler notes its signal), and
:func:`sigterm_raises`, around each command, hands it on as the stop it is.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

from cdpr_twin.files.transaction import Terminated


class _Stops:
    """The stop under way in this process: which signal began it, and how deep the handling is."""

    first: int | None = None
    """The signal (SIGINT, SIGTERM) that began the stop under way; ``None``: none yet."""
    depth = 0
    """How many :func:`sigterm_raises` (or :func:`handle_stops`, for good) are entered."""


def _stop(signum: int, frame) -> None:
    """SIGINT and SIGTERM, while handled: the first raises its stop, later ones are ignored."""
    if _Stops.first is not None:
        return  # a stop is under way: it decides the status and the exit code
    _Stops.first = signum
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM ``exc`` is, or that surfaced as it; else ``None``.

    A plain ``KeyboardInterrupt`` after a SIGTERM (a library re-raised its
    :class:`~cdpr_twin.files.transaction.Terminated` as the base class) is a ``Terminated``.
    """
    stop = exc if isinstance(exc, KeyboardInterrupt) else None
    if isinstance(exc, SystemError) and isinstance(exc.__cause__, KeyboardInterrupt):
        stop = exc.__cause__
    if stop is not None and not isinstance(stop, Terminated) and _Stops.first == signal.SIGTERM:
        return Terminated()
    return stop


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within: SIGTERM raises :class:`~.Terminated`, Ctrl-C ``KeyboardInterrupt``.

    The first of them only (SIGINT left ignored if it is): a later SIGINT or SIGTERM is ignored
    while the stop completes the outputs (the first decides the status and the exit code).
    Restored on leaving, and the stop forgotten when the outermost one is left (a later Ctrl-C
    is a new stop). The main thread only. A Ctrl-C or SIGTERM that surfaced otherwise
    (:func:`interruption`) leaves as itself.
    """
    if _Stops.depth == 0:
        _Stops.first = None
    _Stops.depth += 1
    previous = {sig: signal.signal(sig, _stop) for sig in _handled()}
    try:
        yield
    except (SystemError, KeyboardInterrupt) as exc:
        if (stop := interruption(exc)) is None or stop is exc:
            raise
        raise stop from None
    finally:
        for sig, handler in previous.items():
            if handler is not None:  # (None: a handler installed from C, not restorable)
                signal.signal(sig, handler)
        _Stops.depth -= 1
        if _Stops.depth == 0:
            _Stops.first = None  # a later Ctrl-C, outside this command, is a Ctrl-C


def handle_stops() -> None:
    """For good, in this process (the command's entry point): as :func:`sigterm_raises`.

    Installed before anything heavy is imported, so that a Ctrl-C or SIGTERM during start-up
    is a stop like any other. The main thread only.
    """
    _Stops.depth += 1
    for sig in _handled():
        signal.signal(sig, _stop)


def _handled() -> tuple[int, ...]:
    """The signals to handle: SIGTERM, and SIGINT unless it is ignored.

    A shell starts a background job (``cdpr-twin run … &`` in a script) with SIGINT ignored, so
    that a Ctrl-C meant for the foreground spares it; Python keeps it ignored, and so do we.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return (signal.SIGTERM,)
    return (signal.SIGINT, signal.SIGTERM)


def settle() -> None:
    """From now on every SIGINT and SIGTERM is ignored: the command's exit code is decided.

    Ignored by the system, not by a handler: Python puts back the default action of the signals
    it handles as the interpreter exits, and that (a second or so of threads and modules ending)
    a SIGTERM would then end with status 143 after the command said "interrupted". The main
    thread only.
    """
    if _Stops.first is None:
        _Stops.first = 0
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


@contextlib.contextmanager
def shielded(escape: bool = False) -> Iterator[None]:
    """Within: SIGINT and SIGTERM are held off, so that the outputs being saved are completed.

    A run completes, renames and commits its files in well under a second; a (second) Ctrl-C
    or SIGTERM during that used to interrupt it, leaving ``*.partial`` files and the lock. A
    signal that came is delivered on leaving, to the handler it was meant for, unless it is of
    the kind of a stop already under way (which absorbs it); also when the body raised (the
    stop came first: it is the one that leaves). Within :func:`sigterm_raises` a signal of the
    other kind is delivered to its handler, which ignores it: the first stop decides (a pool
    worker's default SIGTERM, its parent's order to stop, still ends it). SIGKILL still stops
    it. In another thread
    than the main one (where signals cannot be handled) it does nothing.

    Args:
        escape: a second signal while one is held is not held: the first one held is handled
            at once (a body that hangs can still be stopped without SIGKILL; the first decides
            which stop it is).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous: dict = {}

    def hold(signum, frame) -> None:
        held.append(signum)
        first = held[0]
        if escape and len(held) > 1 and callable(meant := previous.get(first)):
            meant(first, frame)  # raises (Ctrl-C, Terminated) here, in the body

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
        for came in dict.fromkeys(held):  # each kind once, in the order they came
            if not (isinstance(stopping, KeyboardInterrupt) and came == absorbed):
                signal.raise_signal(came)  # now, to the handler it was meant for (a worker: exit)


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
