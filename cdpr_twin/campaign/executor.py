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

import contextlib
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Generator, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from cdpr_twin.files.transaction import Terminated


class ExecutorError(RuntimeError):
    """The executor cannot start (e.g. Ray is not installed)."""


def run_local(
    fn: Callable[..., Any], items: Iterable[Any], workers: int, *args: Any
) -> Generator[Any, None, None]:
    """``fn(item, *args)`` for every item in ``workers`` spawned processes; results as they end.

    At most ``2 × workers`` items are in flight, so a stop (Ctrl-C, SIGTERM) abandons few.
    """
    ctx = multiprocessing.get_context("spawn")
    pending: set = set()
    todo = iter(items)
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=exit_with, initargs=(os.getpid(),)
    ) as pool:
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
            abandon(pool)  # a stop ends the runs under way, not after them
            raise


def abandon(pool: ProcessPoolExecutor) -> None:
    """Cancel the pool's queued tasks, end its workers now, and wait for its manager thread.

    The pool's own thread cancels the queued tasks (a future cancelled here, then failed by
    that thread as the workers end, is Python 3.11's ``InvalidStateError`` trace); ``shutdown``
    forgets the workers and the thread, so both are taken first. The thread is waited for: one
    still closing its wake-up pipe as the interpreter exits races ``concurrent.futures``' exit
    hook writing to it (``OSError: [Errno 9] Bad file descriptor``, "Exception ignored in
    <module 'threading'>", after the command's last line).
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    stop_workers(pool, processes)
    if manager is not None:
        manager.join(timeout=10.0)


def exit_with(parent: int) -> None:
    """In a worker: end the process when its parent is gone (a killed campaign, SIGKILL).

    A spawned worker outlives a parent killed without cleanup and would simulate on, at full
    CPU, for nobody; a daemon thread polls the parent's pid once a second.
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def stop_workers(
    pool: ProcessPoolExecutor, processes: list | None = None, grace: float = 2.0
) -> None:
    """End the pool's worker processes now (their tasks are abandoned, not recorded).

    ``shutdown`` alone lets every task already handed to a worker finish (40 s for a PBVS run),
    past a supervisor's grace period. Each worker gets SIGTERM; one still alive ``grace``
    seconds later (all share the deadline) is killed. Python ≥ 3.14 has ``terminate_workers``;
    before it the processes are only reachable by the pool's private ``_processes`` (which a
    ``shutdown`` clears: give ``processes``, taken before it, after one).
    """
    given = processes is not None
    if processes is None:
        processes = list((getattr(pool, "_processes", None) or {}).values())
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None and not given:
        terminate()
    else:
        for process in processes:
            process.terminate()
    deadline = time.monotonic() + grace
    for process in processes:
        process.join(timeout=max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(timeout=1.0)  # gone before its run's directory is tidied


CONNECT_TIMEOUT_S = 10.0
"""How long a Ray cluster's address is given to accept a connection before it is refused."""


def check_address(address: str) -> None:
    """Refuse a cluster address that accepts no TCP connection within the timeout.

    ``host:port`` (the head's GCS) and ``ray://host:port`` (Ray Client) are tried; ``auto``
    and other forms are left to Ray.

    Raises:
        ExecutorError: naming the address and the socket's error.
    """
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit() or not host:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise ExecutorError(
            f"cannot start Ray on {address}: nothing accepts a connection there "
            f"({exc.strerror or exc}); start the cluster (ray start --head) or fix the address"
        ) from None


def run_ray(
    fn: Callable[..., Any],
    items: Iterable[Any],
    workers: int | None,
    address: str | None,
    *args: Any,
) -> Generator[Any, None, None]:
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
        if address is not None:
            check_address(address)  # Ray itself retries an unreachable cluster for minutes
        ours, stopped = signal.getsignal(signal.SIGTERM), False
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        except Exception as exc:  # Ray's own connection errors are of many types
            _shutdown(ray)
            where = address or "a local cluster"
            raise ExecutorError(f"cannot start Ray on {where}: {exc}") from None
        except SystemExit as exc:  # Ray's SIGTERM handler, while Ray was starting
            _shutdown(ray)  # (a half-started driver aborts the interpreter at exit)
            if exc.code != signal.SIGTERM:
                raise
            stopped = True
            raise Terminated() from None
        except BaseException:  # the campaign's own stop (SIGTERM, Ctrl-C) before Ray's handler
            _shutdown(ray)
            raise
        finally:  # Ray's SIGTERM handler exits; the campaign's stops it cleanly (exit 143)
            if threading.current_thread() is threading.main_thread() and callable(ours):
                # once stopped, a second SIGTERM is ignored while the outputs are completed
                signal.signal(signal.SIGTERM, signal.SIG_IGN if stopped else ours)
    try:
        n = workers or max(1, int(ray.available_resources().get("CPU", 1)))

        @ray.remote(num_cpus=1)
        class Worker:
            def run(self, item):
                return fn(item, *args)

        # (Ray's stubs type the decorated class as the class, without its .remote())
        pool = ActorPool([Worker.remote() for _ in range(n)])  # type: ignore[attr-defined]
        yield from pool.map_unordered(lambda actor, item: actor.run.remote(item), list(items))
    finally:
        if started:
            ray.shutdown()


def _shutdown(ray) -> None:
    """Disconnect from Ray after a failed start; an error of its own is not the one to tell.

    Ray's processes started before the driver connected are not reached by it: they end with
    this process (Ray ties their lives to their parent's).
    """
    with contextlib.suppress(Exception):
        ray.shutdown()
