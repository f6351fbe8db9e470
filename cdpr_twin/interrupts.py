"""Ctrl-C and SIGTERM seen through compiled code.

SIGTERM raises :class:`~cdpr_twin.outputs.Terminated` (and Ctrl-C ``KeyboardInterrupt``) from
the signal handler, wherever the main thread is. Inside a numba-compiled function the handler
runs when the function hands back, and CPython reports the pair as ``SystemError: …returned a
result with an exception set``, the interrupt as its cause: the run would be recorded as
failed where it was stopped.
"""

from __future__ import annotations


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM ``exc`` is, or that surfaced as it through compiled code; else None."""
    if isinstance(exc, KeyboardInterrupt):
        return exc
    if isinstance(exc, SystemError) and isinstance(exc.__cause__, KeyboardInterrupt):
        return exc.__cause__
    return None
