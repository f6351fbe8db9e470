"""Offscreen GL contexts freed on the thread that made them, whoever drops them.

A ``mujoco.Renderer`` makes its EGL context current on the thread that builds it; freeing it on
another thread fails (``EGL_BAD_ACCESS`` from ``eglMakeCurrent``, printed by its ``__del__``)
and leaks the context. A renderer dropped without ``close()`` is freed by whichever thread's
garbage collection finds it — the camera's worker thread, when that one happens to allocate.
:func:`owned` ties each renderer to its maker: dropped on that thread it is closed at once;
dropped on another it waits in a list until its maker builds the next renderer, or the
interpreter exits.
"""

from __future__ import annotations

import atexit
import threading
import weakref
from typing import Any

_WAITING: list[tuple[int, Any]] = []
"""(thread ident, renderer) of renderers dropped on a thread that did not make them."""
_LOCK = threading.Lock()


def _free(renderer: Any, maker: int) -> None:
    if threading.get_ident() == maker:
        renderer.close()
    else:
        with _LOCK:
            _WAITING.append((maker, renderer))


def free_waiting() -> None:
    """Close the renderers this thread made that other threads dropped."""
    me = threading.get_ident()
    with _LOCK:
        mine = [r for t, r in _WAITING if t == me]
        _WAITING[:] = [(t, r) for t, r in _WAITING if t != me]
    for renderer in mine:
        renderer.close()


def owned(holder: object, renderer: Any) -> weakref.finalize:
    """Free ``renderer`` when ``holder`` is dropped (see the module's docstring).

    Args:
        holder: the object whose lifetime the renderer's follows.
        renderer: a ``mujoco.Renderer`` made on this thread.

    Returns:
        The finalizer: call it to free the renderer now (``close()``), once.
    """
    free_waiting()
    return weakref.finalize(holder, _free, renderer, threading.get_ident())


atexit.register(free_waiting)  # the main thread's, at exit (finalizers run before: LIFO)
