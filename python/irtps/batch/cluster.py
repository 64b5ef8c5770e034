"""The Dask clusters of batches: one on this machine whose worker processes stop cleanly
when interrupted (`local_cluster`), and a client of a running scheduler (`connect`).

Dask (``dask.distributed``) is an optional dependency: ``pip install 'irtps[batch]'``.
"""

from __future__ import annotations

import gc
import logging
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from multiprocessing import resource_tracker

from irtps.batch.task import dask_setup
from irtps.errors import ArgumentError, IrtpsError

__all__ = ["connect", "import_distributed", "local_cluster", "quiet_logging"]

INSTALL_HINT = "pip install 'irtps[batch]'"


@contextmanager
def local_cluster(workers: int | None = None, threads_per_worker: int = 1, *, processes: bool = True) -> Iterator:
    """A Dask cluster on this machine and a client connected to it, closed on exit.

    Parameters
    ----------
    workers : int, optional
        Worker processes; default one per core divided by ``threads_per_worker``.
    threads_per_worker : int
        Data sets each worker reconstructs at once. Worker processes get
        ``RAYON_NUM_THREADS`` set to it, so that the Rust core (image decoding,
        photometric stereo, ray tracing) runs as many threads as the worker runs tasks
        and the workers together use each core once.
    processes : bool
        Workers as separate processes (default); False runs them as threads of this
        process (for tests; the Rust core then uses this process's thread count).

    Notes
    -----
    The worker processes ignore SIGINT (a terminal's Ctrl-C reaches the whole process
    group): this process handles the interrupt and closes the cluster. A worker asked to
    close while it runs `irtps.batch.task.reconstruct_to_folder` finishes the output folder
    it is writing, if any, and exits at once (SIGTERM does the same); the worker processes
    are gone when the ``with`` block is left. Leaving it on an exception (e.g. KeyboardInterrupt) closes
    the cluster with the logs of Dask, Tornado and asyncio silenced and SIGINT and SIGTERM
    ignored (in the main thread) until it is closed. A SIGINT or SIGTERM that comes while
    the worker processes start is handled once they have started (then closed), so that
    no half-started cluster is left; the worker processes start with SIGINT blocked, so
    a terminal's Ctrl-C never reaches one still importing.

    The scheduler gives a worker no more tasks than it has threads while other tasks
    wait (``distributed.scheduler.worker-saturation`` 1.0, not Dask's 1.1): Dask charges
    a worker's death to every task the worker holds, and a data set waiting behind one
    that kills its worker each time would fail with it (``KilledWorker``). Dask holds
    tasks back so only in batches of more than twice as many data sets as threads, and
    sends the first of them to the workers at once.

    Yields
    ------
    distributed.Client

    Raises
    ------
    ArgumentError
        If ``workers`` or ``threads_per_worker`` is below 1.
    IrtpsError
        If dask is not installed.

    Examples
    --------
    >>> with local_cluster(2, processes=False) as client:
    ...     len(client.scheduler_info()["workers"])
    2
    """
    if workers is not None and workers < 1:
        raise ArgumentError("workers", f"must be at least 1, not {workers}")
    if threads_per_worker < 1:
        raise ArgumentError("threads_per_worker", f"must be at least 1, not {threads_per_worker}")
    distributed = import_distributed()
    import dask  # installed with distributed

    worker_options = (
        {"env": {"RAYON_NUM_THREADS": str(threads_per_worker)}, "preload": [dask_setup.__module__]} if processes else {}
    )
    cluster = client = None
    try:
        # no dashboard; the scheduler's HTTP server (health checks) on a free port: no
        # "Port 8787 is already in use" warning when another cluster runs on this machine
        scheduler_options = {"dashboard_address": "localhost:0"}
        with _signals_held(processes), dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
            cluster = distributed.LocalCluster(
                n_workers=workers,
                threads_per_worker=threads_per_worker,
                processes=processes,
                dashboard_address=None,
                scheduler_kwargs=scheduler_options,
                **worker_options,
            )
        client = distributed.Client(cluster)
        yield client
    except BaseException:
        with _shielded(), quiet_logging():
            _close(client, cluster)
        raise
    _close(client, cluster)


@contextmanager
def connect(address: str) -> Iterator:
    """A client of a running Dask scheduler, closed on exit.

    Parameters
    ----------
    address : str
        The scheduler's address, e.g. ``"tcp://head-node:8786"``.

    Yields
    ------
    distributed.Client

    Raises
    ------
    IrtpsError
        If the scheduler cannot be reached, or dask is not installed.
    """
    distributed = import_distributed()
    failure = None
    try:
        client = distributed.Client(address)
    except (OSError, ValueError) as error:
        failure = f"{address}: cannot reach a Dask scheduler there ({error})"
    if failure is not None:
        # The half-made client, garbage once the error is, is closed now: collected later,
        # inside another client's start, its closing would wait on the lock that start holds.
        gc.collect()
        raise IrtpsError(failure)
    try:
        yield client
    except BaseException:
        with _shielded(), quiet_logging():
            client.close()
        raise
    client.close()


def _close(client, cluster) -> None:
    """Close a client, then its cluster (either may be None)."""
    try:
        if client is not None:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


@contextmanager
def quiet_logging() -> Iterator[None]:
    """No log record at all for the duration (Dask's, Tornado's, asyncio's teardown chatter)."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(previous)


@contextmanager
def _signals_held(processes: bool) -> Iterator[None]:
    """While a cluster of worker processes starts: SIGINT and SIGTERM held back (recorded,
    then raised again at the end), so that a starting cluster is never left half-built
    (Dask would close it at exit, with a traceback) but built, then closed. Only in the
    main thread (where signals are handled)."""
    if not processes or threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    handlers = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if handler is not None and handler != signal.SIG_IGN:  # None: not set from Python, so not restorable
            handlers[signum] = signal.signal(signum, lambda signum, frame: received.append(signum))
    # SIGINT blocked too: the threads and worker processes started meanwhile inherit the
    # block, so a terminal's Ctrl-C (sent to the whole process group) never reaches a
    # worker still importing; here it waits, pending, until the block is lifted. The
    # resource tracker is started first: starting it unblocks SIGINT in the calling thread.
    resource_tracker.ensure_running()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)  # a pending SIGINT is recorded now
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
        if received:
            signal.raise_signal(received[0])  # now handled as it would have been


@contextmanager
def _shielded() -> Iterator[None]:
    """SIGINT and SIGTERM ignored for the duration, in the main thread (a second Ctrl-C
    must not break off a teardown)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, signal.SIG_IGN) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            if handler is not None:
                signal.signal(signum, handler)


def import_distributed():
    """Dask's ``distributed`` module.

    Raises
    ------
    IrtpsError
        If it is not installed, with how to install it.
    """
    try:
        import distributed
    except ImportError:
        raise IrtpsError(f"batch runs need Dask (dask.distributed), which is not installed: {INSTALL_HINT}") from None
    return distributed
