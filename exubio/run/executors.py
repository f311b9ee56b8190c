"""The executors of a run: ``[fn(item) for item in items]`` in this process, in a pool of local
processes or on Dask (a local cluster or a running scheduler), in the items' order, a failed item
replaced by ``on_error(item, exception)``; Ctrl-C stops the workers and removes their unfinished
files. ``exubio reconstruct`` (several trials) and ``exubio study`` both run on them."""
from __future__ import annotations

import logging
import os
import time
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, Callable

from exubio.errors import InputError
from exubio.run import interrupt

log = logging.getLogger(__name__)


def run_all(fn: Callable, items: list, /, *, jobs: int = 1, scheduler: str | None = None,
            on_error: Callable[[Any, BaseException], Any], on_done: Callable[[Any], None] | None = None) -> list:
    """``[fn(item) for item in items]``: on Dask with ``scheduler``, else in ``jobs`` local
    processes (1: in this process, where an exception propagates)."""
    if scheduler:
        return map_on_scheduler(fn, items, scheduler, on_error=on_error, on_done=on_done)
    if jobs > 1:
        return map_in_processes(fn, items, jobs, on_error=on_error, on_done=on_done)
    out = []
    for item in items:
        out.append(fn(item))
        if on_done is not None:
            on_done(out[-1])
    return out


STOP_WAIT_S = 0.5
"""After Ctrl-C, how long the workers of a process pool get to remove their unfinished files after
SIGTERM before they are killed (what a killed worker leaves, the next run removes)."""


def map_in_processes(fn: Callable, items: list, jobs: int, /, *, on_error: Callable[[Any, BaseException], Any],
                     on_done: Callable[[Any], None] | None = None) -> list:
    """``[fn(item) for item in items]`` in a pool of ``jobs`` local processes, in the items' order; a
    failed item gives ``on_error(item, exception)`` in its place. Ctrl-C reaches this process only
    (the workers ignore SIGINT): the pool is stopped at once, every worker is sent SIGTERM (it then
    stops as on Ctrl-C, removing its unfinished files) and killed after STOP_WAIT_S, and the
    KeyboardInterrupt goes on to the caller (the CLI: one line, exit 130)."""
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=_pool_worker_signals, initargs=(os.getpid(),))
    try:
        with interrupt.kept_from_new_processes():  # a terminal's Ctrl-C reaches the whole process group
            futures: list[Future] = [pool.submit(fn, item) for item in items]
        outs = []
        for f, item in zip(futures, items):
            try:
                outs.append(f.result())
            except Exception as exc:  # noqa: BLE001 - a worker that died fails only its item
                outs.append(on_error(item, exc))
            if on_done is not None:
                on_done(outs[-1])
        pool.shutdown(wait=True)
        return outs
    except BaseException:
        _stop_pool(pool)
        raise


def _pool_worker_signals(parent: int) -> None:
    """In a pool worker: Ctrl-C is the parent's to handle; SIGTERM (the parent stopping the pool)
    removes the temporary files and folders the worker is writing and ends it at once (not by an
    exception, which an Exudyn callback would catch and print). A result set being placed holds
    SIGTERM back until it is complete (exubio.io.results.ResultSet). The worker is sent SIGTERM
    when ``parent`` (the run) dies (Linux: PR_SET_PDEATHSIG): a run killed by SIGKILL left its
    workers finishing their trial into the folder the next run resumed, then waiting forever."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def stop(signum, frame):  # noqa: ARG001 - the signal handler's signature
        from exubio.io.results import remove_in_progress

        remove_in_progress()
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, stop)
    _end_with_parent(parent, signal.SIGTERM)


def _end_with_parent(parent: int, signum: int) -> None:
    """Have this process sent ``signum`` when the process that started it ends (Linux); where
    ``parent`` has ended already (before this was set), end now. Elsewhere nothing."""
    import ctypes
    import ctypes.util
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(1, signum, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    from exubio.io.result_set import _process_runs

    if not _process_runs(parent):
        os.kill(os.getpid(), signum)


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    processes = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown clears them
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        try:
            proc.terminate()
        except (OSError, ValueError):
            pass
    deadline = time.monotonic() + STOP_WAIT_S
    for proc in processes:
        proc.join(timeout=max(deadline - time.monotonic(), 0.0))
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=1.0)


DASK_CLOSE_WAIT_S = 5.0
"""After Ctrl-C, how long a local cluster whose workers were stopped gets to close (measured: 0.45-0.50 s
idle, 1.6 s on a loaded machine). It was 0.5 s: a close cut short left the cluster's event-loop thread
closing while the interpreter ended, and its half-done work (a worker process's semaphores) came out
as multiprocessing's resource-tracker warnings after exubio's one line."""


def _worker_setup() -> None:
    """Imported once per Dask worker: exubio and its solvers stay loaded for every trial."""
    import exubio.methods.ls  # noqa: F401
    import exubio.methods.pf  # noqa: F401
    import exubio.run.pipeline  # noqa: F401


_LOCAL_CLUSTER_CONFIG = {
    # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in the worker processes it spawns, which also fixes
    # glibc's mmap threshold at 128 kB: every array of a trial above that (a 5000-frame trial's
    # marker arrays are 2 MB) is then mapped and unmapped afresh, page faults included (measured:
    # about 0.2 s more system time per 25 s trial). A study's workers run one trial after another
    # and hold no data between them: glibc's defaults suit them.
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    # the statistical profiler samples the task thread's stack every 10 ms (for the dashboard,
    # which a local study cluster does not start)
    "distributed.worker.profile.enabled": False,
}
"""Dask settings of the local clusters ``map_on_scheduler`` starts ("local:N"); a running
scheduler's workers ("tcp://...") keep their own."""


def map_on_scheduler(fn: Callable, items: list, scheduler: str, /, *,
                     on_error: Callable[[Any, BaseException], Any],
                     on_done: Callable[[Any], None] | None = None) -> list:
    """``[fn(item) for item in items]`` on Dask: ``scheduler`` is "local:N" (a local cluster of N
    single-threaded worker processes, started and closed here) or "tcp://HOST:PORT" (a running
    scheduler). Workers import exubio once (``_worker_setup``) and keep it. A failed item gives
    ``on_error(item, exception)`` in its place; results come back in the items' order."""
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:  # pragma: no cover - a dependency of exubio
        raise InputError(f"--scheduler {scheduler}: Dask distributed is not installed ({exc})") from None
    for name in ("distributed", "bokeh", "tornado"):  # their INFO lines are not the user's business
        logging.getLogger(name).setLevel(logging.ERROR)
    cluster = None
    pressed: list = []
    if scheduler.startswith("local:"):
        try:
            n = int(scheduler.split(":", 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"--scheduler {scheduler}: expected local:N with N >= 1 workers")
        import dask

        client = None
        try:
            with interrupt.held_back() as pressed, interrupt.kept_from_new_processes(), dask.config.set(_LOCAL_CLUSTER_CONFIG):
                # silence_logs: also the workers' logs (their processes); dashboard_address: Dask's HTTP server
                # on a free port (None still asks for 8787, and warns on stderr when another cluster holds it),
                # on the loopback only (":0" listened on every interface of the lab's machine)
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL)
                client = Client(cluster)
        except BaseException as exc:  # noqa: BLE001 - a second Ctrl-C, or a start that failed after a first one
            if not (pressed or isinstance(exc, KeyboardInterrupt)):
                raise
            # a terminal's Ctrl-C also reaches the worker processes being spawned (its process group):
            # one that dies of it fails the start ("Nanny failed to start"), which is the Ctrl-C's doing
            _stop_dask(client, cluster, [])
            raise KeyboardInterrupt from exc
    elif scheduler.startswith("tcp://"):
        try:
            client = Client(scheduler, timeout=10)
        except OSError as exc:
            raise InputError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({exc})") from None
    else:
        raise InputError(f"--scheduler {scheduler}: expected local:N or tcp://HOST:PORT")
    futures: dict = {}
    try:
        if pressed:  # Ctrl-C while the local cluster started: it is stopped below, now that it has
            raise KeyboardInterrupt
        client.run(_worker_setup)
        futures = {client.submit(fn, item, pure=False): k for k, item in enumerate(items)}
        out: list = [None] * len(items)
        for f in as_completed(list(futures)):
            k = futures[f]
            try:
                out[k] = f.result()
            except Exception as exc:  # noqa: BLE001 - a worker that died fails only its item
                out[k] = on_error(items[k], exc)
            if on_done is not None:
                on_done(out[k])
        return out
    except KeyboardInterrupt:
        _stop_dask(client, cluster, list(futures))
        cluster = None
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _stop_dask(client: Any, cluster: Any, futures: list, /) -> None:
    """After Ctrl-C: cancel the work, close the client (0.5 s) and the local cluster (DASK_CLOSE_WAIT_S),
    and say nothing of the connections that close meanwhile (Dask logs them as errors)."""
    _quiet_dask_exit()
    if cluster is not None:  # a local cluster's worker processes are this process's children: stopped now
        import multiprocessing

        workers = multiprocessing.active_children()
        for proc in workers:
            proc.terminate()
        deadline = time.monotonic() + STOP_WAIT_S
        for proc in workers:
            proc.join(timeout=max(deadline - time.monotonic(), 0.0))
            if proc.is_alive():
                proc.kill()
    for step in (lambda: client.cancel(futures, force=True) if client is not None else None,
                 lambda: client.close(timeout=0.5) if client is not None else None,
                 lambda: cluster.close(timeout=DASK_CLOSE_WAIT_S) if cluster is not None else None):
        try:
            step()
        except BaseException:  # noqa: BLE001 - stopping: whatever Dask raises while it closes goes unsaid
            pass


def _quiet_dask_exit() -> None:
    """Say nothing of what Dask reports while it stops after Ctrl-C: its loggers off, and its exit
    hook (which would close a half-started or half-closed cluster again and print why it cannot)
    unregistered."""
    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    try:
        import atexit

        from distributed.deploy.spec import close_clusters

        atexit.unregister(close_clusters)
    except ImportError:  # pragma: no cover - another layout of distributed
        pass
