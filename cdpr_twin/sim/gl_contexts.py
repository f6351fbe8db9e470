"""Offscreen GL contexts freed on the thread that made them, whoever drops them.

A ``mujoco.Renderer`` makes its EGL context current on the thread that builds it; freeing it on
another thread fails (``EGL_BAD_ACCESS`` from ``eglMakeCurrent``, printed by its ``__del__``)
and leaks the context. A renderer dropped without ``close()`` is freed by whichever thread's
garbage collection finds it — the camera's worker thread, when that one happens to allocate.
:func:`owned` ties each renderer to its maker thread: dropped there it is closed at once;
dropped on another it waits until its maker builds its next renderer (the main thread's also
at exit). A renderer whose maker thread has ended waits for good: no thread may free it.
"""

from __future__ import annotations

import atexit
import queue
import threading
import weakref
from typing import Any

_WAITING: queue.SimpleQueue = queue.SimpleQueue()
"""(maker thread, renderer) dropped on another thread. A ``SimpleQueue``: a finalizer may run
inside any code, :func:`free_waiting` included (a lock there could be its own thread's)."""


def _free(renderer: Any, maker: threading.Thread) -> None:
    if threading.current_thread() is maker:
        renderer.close()
    else:
        _WAITING.put((maker, renderer))


def free_waiting() -> None:
    """Close the renderers this thread made that other threads dropped."""
    me, others = threading.current_thread(), []
    while True:
        try:
            maker, renderer = _WAITING.get_nowait()
        except queue.Empty:
            break
        if maker is me:
            renderer.close()
        else:
            others.append((maker, renderer))
    for item in others:
        _WAITING.put(item)


def owned(holder: object, renderer: Any) -> weakref.finalize:
    """Free ``renderer`` when ``holder`` is dropped (see the module's docstring).

    Args:
        holder: the object whose lifetime the renderer's follows.
        renderer: a ``mujoco.Renderer`` made on this thread.

    Returns:
        The finalizer: call it to free the renderer now (``close()``), once.
    """
    free_waiting()
    return weakref.finalize(holder, _free, renderer, threading.current_thread())


atexit.register(free_waiting)  # on the main thread: what it made and others dropped
