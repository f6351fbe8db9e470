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
import os
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any, ClassVar

from cdpr_twin.files.transaction import Terminated


class _Stops:
    """The stop under way in this process: which signal began it, and how deep the handling is."""

    first: int | None = None
    """The signal (SIGINT, SIGTERM) that began the stop under way; ``None``: none yet."""
    depth = 0
    """How many :func:`sigterm_raises` (or :func:`handle_stops`, for good) are entered."""
    ours: tuple[int, int] | None = None
    """(process id, main thread id) while :func:`_stop` (or :func:`_relay`) handles SIGINT and
    SIGTERM (or a signal is ignored) in that process: a :class:`Shield` then holds signals
    without swapping the handlers (one is entered every control tick); ``None``: another
    handler may be installed."""
    held: ClassVar[list[int]] = []
    """The signals held by the shields entered on that path, in the order they came."""
    escapes: ClassVar[list[bool]] = []
    """Each shield entered on that path, innermost last: whether a second signal escapes."""


class _Relay:
    """The handlers :func:`held_here` relays SIGINT and SIGTERM to, by signal."""

    to: ClassVar[dict[int, Any]] = {}


def _held(signum: int, frame) -> int | None:
    """Within a shield of the fast path: hold ``signum``; the signal to handle now, or ``None``.

    A second signal, where the innermost shield lets it escape, is the first one held, now.
    """
    held = _Stops.held
    held.append(signum)
    if not (_Stops.escapes[-1] and len(held) > 1):
        return None
    return held[0]


def _relay(signum: int, frame) -> None:
    """Within :func:`held_here`: hold the signal in a shield, else hand it on as it was meant."""
    if _Stops.escapes:
        now = _held(signum, frame)
        if now is None:
            return
        signum = now
    handler = _Relay.to.get(signum)
    if callable(handler):
        handler(signum, frame)
    elif handler == signal.SIG_DFL:
        # the system's action (SIGTERM: the process ends), as if no handler had been set
        signal.signal(signum, signal.SIG_DFL)
        signal.raise_signal(signum)


@contextlib.contextmanager
def held_here() -> Iterator[None]:
    """Within: one handler, installed once, serves every :class:`Shield` (a run's tick loop).

    A shield entered every control tick would otherwise swap the handlers of SIGINT and SIGTERM
    twice a tick. Within this block a signal outside any shield goes at once to the handler
    that was installed before it (ignored if it was ignored, the system's action if it was the
    default); within a shield it is held, as :class:`Shield` says. Nothing changes where this
    module's own handler is already installed (a command) or off the main thread.
    """
    here = (os.getpid(), threading.get_ident())
    if _Stops.ours == here or threading.current_thread() is not threading.main_thread():
        yield
        return
    outer, ours = dict(_Relay.to), _Stops.ours
    handled = (signal.SIGINT, signal.SIGTERM)
    previous: dict[int, Any] = {sig: signal.getsignal(sig) for sig in handled}
    if any(handler is None for handler in previous.values()):
        # a handler installed from C cannot be handed on: each shield swaps handlers
        yield
        return
    _Relay.to = previous
    for sig in previous:
        signal.signal(sig, _relay)
    _Stops.ours = here
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _Relay.to, _Stops.ours = outer, ours


def _stop(signum: int, frame) -> None:
    """SIGINT and SIGTERM, while handled: the first raises its stop, later ones are ignored.

    Within a :class:`shielded` block the signal is held instead; a second one, where the
    innermost shield lets it escape, handles the first one held now.
    """
    if _Stops.escapes:
        now = _held(signum, frame)
        if now is None:
            return
        signum = now
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
    _Stops.ours = _ours_now()
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
        _Stops.ours = _ours_now()
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
    _Stops.ours = _ours_now()


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
    _Stops.ours = _ours_now()


def _ours_now() -> tuple[int, int] | None:
    """:attr:`_Stops.ours` as the handlers are now (called where this module changes them)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) not in (_stop, signal.SIG_IGN):
            return None
    return os.getpid(), threading.get_ident()


class Shield:
    """Within: SIGINT and SIGTERM are held off, so that the outputs being saved are completed.

    A run completes, renames and commits its files in well under a second; a (second) Ctrl-C
    or SIGTERM during that used to interrupt it, leaving ``*.partial`` files and the lock. A
    signal that came is delivered on leaving, to the handler it was meant for, unless it is of
    the kind of a stop already under way (which absorbs it); also when the body raised (the
    stop came first: it is the one that leaves). Within :func:`sigterm_raises` a signal of the
    other kind is delivered to its handler, which ignores it: the first stop decides (a pool
    worker's default SIGTERM, its parent's order to stop, still ends it). SIGKILL still stops
    it. In another thread than the main one (where signals cannot be handled) it does nothing.

    Where this module's handler is the one installed (within :func:`sigterm_raises` or after
    :func:`handle_stops`, in the process that installed it) the handler itself holds the
    signals while a shield is entered; elsewhere each shield installs a holding handler and
    puts the previous one back on leaving. Either way the same signals are delivered.

    Args:
        escape: a second signal while one is held is not held: the first one held is handled
            at once (a body that hangs can still be stopped without SIGKILL; the first decides
            which stop it is).
    """

    __slots__ = ("_fast", "_held", "_previous", "_start", "escape")

    def __init__(self, escape: bool = False) -> None:
        self.escape = escape

    def __enter__(self) -> None:
        self._fast = _Stops.ours is not None and _Stops.ours == (os.getpid(), threading.get_ident())
        if self._fast:
            self._start = len(_Stops.held)
            _Stops.escapes.append(self.escape)
            return
        self._previous: dict = {}
        self._held: list[int] = []
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._hold)

    def _hold(self, signum: int, frame) -> None:
        """The holding handler of the path that swaps handlers."""
        held = self._held
        held.append(signum)
        first = held[0]
        if self.escape and len(held) > 1 and callable(meant := self._previous.get(first)):
            meant(first, frame)  # raises (Ctrl-C, Terminated) here, in the body

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._fast:
            _Stops.escapes.pop()
            held = _Stops.held[self._start :]
            del _Stops.held[self._start :]
        else:
            for sig, handler in self._previous.items():
                if handler is not None:  # (None: a handler installed from C, not restorable)
                    signal.signal(sig, handler)
            held = self._held
        if not held:
            return
        # raised in the body, or a stop under way around it
        stopping = exc if exc is not None else sys.exc_info()[1]
        absorbed = signal.SIGTERM if isinstance(stopping, Terminated) else signal.SIGINT
        for came in dict.fromkeys(held):  # each kind once, in the order they came
            if not (isinstance(stopping, KeyboardInterrupt) and came == absorbed):
                if self._fast and _Stops.escapes:
                    _Stops.held.append(came)  # an outer shield holds it in turn
                else:
                    signal.raise_signal(came)  # now, to the handler it was meant for


def shielded(escape: bool = False) -> Shield:
    """Hold SIGINT and SIGTERM off within a ``with`` block (see :class:`Shield`)."""
    return Shield(escape)


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
