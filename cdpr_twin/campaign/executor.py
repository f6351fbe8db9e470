"""Where a campaign's runs execute: local spawned processes (default) or a Ray cluster.

Both take the same tasks and the same worker function and yield results as runs end, in any
order; neither is a scheduler of ours. Local: :class:`concurrent.futures.ProcessPoolExecutor`
with the ``spawn`` start method (a forked child would inherit the parent's Rerun/EGL threads'
locks). Ray (``pip install -e '.[ray]'``): an :class:`ray.util.ActorPool` of actors, one per
CPU the cluster offers (or ``workers``), each importing the package once and running tasks
fed to it; ``ray.init()`` with no address starts a local multi-process cluster (Ray's local
mode is gone), ``address`` joins an existing one.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any


class ExecutorError(RuntimeError):
    """The executor cannot start (e.g. Ray is not installed)."""


def run_local(
    fn: Callable[..., Any], items: Iterable[Any], workers: int, *args: Any
) -> Iterator[Any]:
    """``fn(item, *args)`` for every item in ``workers`` spawned processes; results as they end.

    At most ``2 × workers`` items are in flight, so a stop (Ctrl-C, SIGTERM) abandons few.
    """
    ctx = multiprocessing.get_context("spawn")
    pending: set = set()
    todo = iter(items)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        try:
            for item in todo:
                pending.add(pool.submit(fn, item, *args))
                while len(pending) >= 2 * workers:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    yield from (f.result() for f in done)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                yield from (f.result() for f in done)
        except BaseException:
            for f in pending:
                f.cancel()
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def run_ray(
    fn: Callable[..., Any],
    items: Iterable[Any],
    workers: int | None,
    address: str | None,
    *args: Any,
) -> Iterator[Any]:
    """``fn(item, *args)`` for every item on a Ray cluster's actors; results as they end.

    Raises:
        ExecutorError: Ray is not installed, or the cluster cannot be reached.
    """
    try:
        import ray
        from ray.util import ActorPool
    except ImportError:
        raise ExecutorError(
            "--ray needs Ray: pip install -e '.[ray]' (or pip install 'ray>=2.40')"
        ) from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        except Exception as exc:  # Ray's own connection errors are of many types
            where = address or "a local cluster"
            raise ExecutorError(f"cannot start Ray on {where}: {exc}") from None
    try:
        n = workers or max(1, int(ray.available_resources().get("CPU", 1)))

        @ray.remote(num_cpus=1)
        class Worker:
            def run(self, item):
                return fn(item, *args)

        pool = ActorPool([Worker.remote() for _ in range(n)])
        yield from pool.map_unordered(lambda actor, item: actor.run.remote(item), list(items))
    finally:
        if started:
            ray.shutdown()
