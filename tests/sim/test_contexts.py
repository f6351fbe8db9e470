"""A camera dropped without ``close()`` frees its GL context on the thread that made it.

Before: a Gymnasium environment with the acrobot profile, dropped unclosed, left its renderer to
whichever thread's garbage collection found it — the camera's worker thread — where MuJoCo's
``Renderer.__del__`` failed with ``EGL_BAD_ACCESS`` (printed, "Exception ignored") and the
context leaked (RSS +20–60 MB per environment). Here the drop on another thread is made
deterministic: the only reference is deleted inside a thread.
"""

import gc
import sys
import threading
import weakref
from pathlib import Path

from cdpr_twin.sim import camera, gl_contexts
from cdpr_twin.sim.model import build_model

MODEL = Path(__file__).resolve().parents[2] / "models" / "acrobot" / "scene.xml"


def _drop_in_thread(obj_box: list) -> None:
    t = threading.Thread(target=obj_box.clear)  # the last reference dies on that thread
    t.start()
    t.join()


def _waiting() -> list:
    """What waits for its maker thread (taken out of the queue and put back, in order)."""
    items = []
    while not gl_contexts._WAITING.empty():
        items.append(gl_contexts._WAITING.get_nowait())
    for item in items:
        gl_contexts._WAITING.put(item)
    return items


def test_a_renderer_dropped_on_another_thread_waits_for_its_maker(monkeypatch):
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    model = build_model(MODEL)
    box = [camera.CameraRenderer(model)]
    gl = weakref.ref(box[0]._renderer)  # not a reference that would keep it alive
    _drop_in_thread(box)
    gc.collect()
    assert not unraisable  # before: EGLError(EGL_BAD_ACCESS, eglMakeCurrent) from __del__
    assert gl() is not None and gl()._gl_context is not None  # not freed there: it waits
    assert any(r is gl() for _, r in _waiting())
    other = camera.CameraRenderer(model)  # its maker builds the next one: freed then
    assert gl() is None or gl()._gl_context is None
    assert not any(r is gl() for _, r in _waiting())
    other.close()
    other.close()  # twice is fine
    assert other._renderer is None and not unraisable


def test_a_renderer_dropped_on_its_own_thread_is_freed_at_once():
    model = build_model(MODEL)
    r = camera.CameraRenderer(model)
    gl = r._renderer
    del r
    gc.collect()
    assert gl._gl_context is None and gl._mjr_context is None


def test_a_drop_during_the_drain_is_kept_for_its_maker():
    """A finalizer may run inside any code, the waiting list's own drain included (cyclic GC
    on allocation): what it queues then is neither lost nor freed on the wrong thread, and
    another thread's drain finishes. (The deadlock a lock there allowed — GC inside the
    locked section — is ruled out by having no lock, not reproduced here.)"""
    model = build_model(MODEL)
    box = [camera.CameraRenderer(model)]
    gl = weakref.ref(box[0]._renderer)
    _drop_in_thread(box)  # it waits for this thread
    other_thread = threading.Thread(target=lambda: None)
    gl_contexts._WAITING.put((other_thread, object()))  # someone else's, put back by the drain
    dropped_during = []

    class Reentrant:  # dropped while the drain runs: its finalizer queues from inside it
        def close(self) -> None:
            dropped_during.append(True)
            gl_contexts._free(object(), other_thread)

    gl_contexts._WAITING.put((threading.current_thread(), Reentrant()))
    done = threading.Event()
    t = threading.Thread(target=lambda: (gl_contexts.free_waiting(), done.set()))
    gl_contexts.free_waiting()  # this thread's two: the renderer and the re-entrant one
    assert dropped_during and (gl() is None or gl()._gl_context is None)
    assert sum(maker is other_thread for maker, _ in _waiting()) == 2
    t.start()
    assert done.wait(10.0)  # another thread's drain finishes
    while not gl_contexts._WAITING.empty():  # leave nothing of this test behind
        gl_contexts._WAITING.get_nowait()
