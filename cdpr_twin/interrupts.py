"""Ctrl-C and SIGTERM seen through compiled code.

SIGTERM raises :class:`~cdpr_twin.outputs.Terminated` (and Ctrl-C ``KeyboardInterrupt``) from
the signal handler, wherever the main thread is. Inside a numba-compiled function the handler
runs when the function hands back, and CPython reports the pair as ``SystemError: …returned a
result with an exception set``, the interrupt as its cause: the run would be recorded as
failed where it was stopped. :func:`sigterm_raises`, around each command, hands either on as
the stop it is.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

from cdpr_twin.outputs import Terminated


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM ``exc`` is, or that surfaced as it through compiled code; else None."""
    if isinstance(exc, KeyboardInterrupt):
        return exc
    if isinstance(exc, SystemError) and isinstance(exc.__cause__, KeyboardInterrupt):
        return exc.__cause__
    return None


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within: SIGTERM raises :class:`~cdpr_twin.outputs.Terminated`; restored on leaving.

    Once: a second SIGTERM is ignored while the outputs are completed. The main thread only.
    A Ctrl-C or SIGTERM that surfaced through compiled code (:func:`interruption`) leaves as
    itself, not as the ``SystemError`` that carried it.
    """

    def handler(signum, frame) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    except SystemError as exc:
        if (stop := interruption(exc)) is None:
            raise
        raise stop from None
    finally:
        signal.signal(signal.SIGTERM, previous)
