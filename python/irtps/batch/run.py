"""Batch runs: reconstruct many data sets on a Dask cluster, one task per data set.

A task receives a data set's *path* and its output folder's path: the worker reads the
data set and writes the reconstruction itself, atomically, so the workers must see the
same file system as the client, under the same paths. A data set that fails is reported
with its error and the others go on. The warnings of a task (e.g. saturated
observations) travel back with its result and are issued again on the client.

A worker process that dies while it reconstructs a data set (killed, out of memory) does
not lose the data set: Dask's nanny starts the worker again and the scheduler runs the
task again, on another worker or the restarted one, up to
``distributed.scheduler.allowed-failures`` times (3 by default); each data set's result
records how many workers it lost (`BatchResult.lost_workers`). A data set that kills
every worker that runs it fails with a ``KilledWorker`` error and the others go on. A
resumed batch (``resume=True``) keeps every output folder that is already complete.

An interrupted batch (Ctrl-C, SIGTERM) on a `local_cluster` stops its worker processes
before it returns: a worker writing an output folder finishes that write, then exits
at once without waiting for the reconstruction under way; the worker processes leave
SIGINT to the client process (a terminal sends it to them too), and the teardown logs
nothing.

Dask (``dask.distributed``) is an optional dependency: ``pip install 'irtps[batch]'``.
"""

from __future__ import annotations

import builtins
import gc
import json
import logging
import multiprocessing
import os
import re
import signal
import sys
import threading
import time
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from multiprocessing import resource_tracker
from pathlib import Path

from irtps._shared.atomic import atomic_write_text
from irtps.io.dataset import load_ground_truth
from irtps.io.dataset_files import dataset_image_names
from irtps.errors import ArgumentError, IrtpsError, IrtpsWarning
from irtps.model.metrics import evaluate
from irtps.io.image_selection import parse_image_list, select_images
from irtps.model.options import ReconstructOptions
from irtps._shared.paths import resolve_path
from irtps._shared.records import BATCH, stamp
from irtps.irt.folder import indirect_file_names, load_reconstruction, load_run_record, save_reconstruction
from irtps.irt.reconstruct import load_and_reconstruct

__all__ = [
    "BatchResult",
    "connect",
    "local_cluster",
    "output_names",
    "reconstruct_many",
    "reconstruct_to_folder",
    "summary_table",
    "write_summary",
]

INSTALL_HINT = "pip install 'irtps[batch]'"
SUMMARY_JSON = "batch.json"
SUMMARY_MARKDOWN = "batch.md"


@dataclass(frozen=True)
class BatchResult:
    """What became of one data set of a batch.

    Attributes
    ----------
    name : str
        Its output folder's name under the batch's output folder.
    source : str
        The data set folder, as read by the worker.
    status : str
        ``"ok"``, ``"reused"`` (a resumed batch kept its complete output folder) or
        ``"failed"``.
    seconds : float or None
        Time spent on the worker (reading, reconstructing, writing, evaluating; for a
        reused output, checking and evaluating it); None when the task did not report
        back (e.g. every worker that ran it died).
    error : str or None
        Why it failed: the error message, which names the file or field concerned.
    metrics : dict or None
        The errors against the data set's ground truth (`irtps.model.metrics.Metrics.to_dict`);
        None without ground truth or on failure.
    warnings : tuple of str
        The warnings raised while the worker read, reconstructed and wrote the data set,
        each once, in order: the message of an `irtps.IrtpsWarning` (which names the file
        concerned), ``"Category: message"`` for another warning (``RuntimeWarning``, or
        ``module.Category`` outside the builtins). Empty for a reused output.
    lost_workers : int
        How many times a worker died (killed, out of memory) while it held this data
        set's task, which then ran again.
    robust_used : str or None
        The robust mode of its photometric stereo (`irtps.Reconstruction.robust_used`:
        what ``"auto"`` chose); None on failure, or for a reused output written by a
        version of irtps that did not record it.
    """

    name: str
    source: str
    status: str
    seconds: float | None
    error: str | None = None
    metrics: dict | None = None
    warnings: tuple[str, ...] = ()
    lost_workers: int = 0
    robust_used: str | None = None

    @property
    def failed(self) -> bool:
        """Whether the data set failed."""
        return self.status == "failed"

    @property
    def mean_angular_error(self) -> float | None:
        """The mean angular normal error in degrees, when ground truth gave one."""
        return None if self.metrics is None else self.metrics["normal_mean_angular_deg"]


def output_names(paths: Sequence[str | Path]) -> list[str]:
    """Distinct output folder names for data set folders: their base names, with ``-2``,
    ``-3`` … added to repeats.

    Parameters
    ----------
    paths : sequence of str or pathlib.Path

    Returns
    -------
    list of str
        One name per path, in order; none is ``batch.json`` or ``batch.md``.

    Examples
    --------
    >>> output_names(["a/ball", "b/ball", "cap", "ball-2"])
    ['ball', 'ball-2', 'cap', 'ball-2-2']
    """
    taken = {SUMMARY_JSON, SUMMARY_MARKDOWN}
    names = []
    for path in paths:
        base = resolve_path(path).name
        name, suffix = base, 2
        while name in taken:
            name, suffix = f"{base}-{suffix}", suffix + 1
        taken.add(name)
        names.append(name)
    return names


def reconstruct_to_folder(
    source: str,
    destination: str,
    options: ReconstructOptions,
    *,
    resume: bool = False,
    exclude_images: str | None = None,
) -> BatchResult:
    """Reconstruct one data set folder into an output folder: the task of a batch.

    Errors are caught and reported, never raised, so that one bad data set does not
    stop a batch; warnings are recorded in the result (`BatchResult.warnings`), not
    shown.

    With ``resume``, an output folder that is already complete is kept as it is (and
    evaluated against the ground truth, if any): its ``run.json``, written last by
    `irtps.save_reconstruction`, is valid and records the same data set folder and the
    same options (an option left unset, resolved for each data set, matches any value)
    and left out the images that `exclude_images` names, no other; its normal, albedo and
    height maps and its mask read back, all of one size; its two meshes are files that are
    not empty; and when the chosen IRT-PS pass is not pass 0, ``indirect/`` holds a file for
    each image fitted (`irtps.irt.folder.indirect_file_names`), none empty. Any other output
    folder is reconstructed again and replaced.

    Parameters
    ----------
    source : str
        The data set folder.
    destination : str
        The reconstruction folder to write (atomically, as `irtps.save_reconstruction`).
    options : ReconstructOptions
        How to reconstruct (`irtps.model.options.ReconstructOptions`).
    resume : bool
        Keep a complete output folder (status ``"reused"``) instead of replacing it.
    exclude_images : str, optional
        Images of the data set to leave out, not read (`irtps.load_dataset`).

    Returns
    -------
    BatchResult
        Named after ``destination``'s last part.

    Examples
    --------
    >>> outcome = reconstruct_to_folder("no/such/folder", "out/folder", ReconstructOptions())
    >>> outcome.status, outcome.error
    ('failed', 'no/such/folder: no such data set folder')
    """
    name = Path(destination).name
    start = time.perf_counter()
    with _TASKS.running(), _recorded_warnings() as recorded:
        try:
            kept = _complete_output(destination, source, options, exclude_images) if resume else None
            if kept is None:
                status = "ok"
                dataset, result = load_and_reconstruct(source, options=options, exclude_images=exclude_images)
                with _TASKS.writing():
                    save_reconstruction(result, destination, source=str(resolve_path(source)))
                gt, normals, albedo, height, mask = (
                    dataset.gt,
                    result.normals,
                    result.albedo,
                    result.height,
                    result.mask,
                )
                robust_used = result.robust_used
            else:
                status = "reused"
                (normals, albedo, height, mask), robust_used = kept
                gt = load_ground_truth(source, mask.shape)
            metrics = (
                None
                if gt is None
                else evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=gt).to_dict()
            )
        except Exception as error:  # a batch reports every failure of a data set and goes on
            outcome = BatchResult(name, source, "failed", time.perf_counter() - start, error=_describe(error))
        else:
            outcome = BatchResult(
                name, source, status, time.perf_counter() - start, metrics=metrics, robust_used=robust_used
            )
    return _with_warnings(outcome, recorded)


def reconstruct_many(
    datasets: Sequence[str | Path],
    out: str | Path,
    options: ReconstructOptions | None = None,
    *,
    client=None,
    progress: bool = False,
    resume: bool = False,
    exclude_images: str | Mapping[str, str | None] | None = None,
    **settings,
) -> list[BatchResult]:
    """Reconstruct many data set folders on a Dask cluster, each into ``out/NAME/``.

    Each data set is one task, started in the order given (as workers are free); the
    worker reads the folder and writes
    ``out/NAME/`` (as `irtps.save_reconstruction`, atomically) itself, with ``NAME``
    from `output_names`. A failed data set is reported in its `BatchResult`; the others
    go on. Nothing is written for a failed data set: an output from an earlier run
    stays as it was. The warnings of each task are issued again here as it completes,
    as ``NAME: message`` (an `irtps.IrtpsWarning`, or the worker warning's category).

    A worker that dies while it holds a task (killed, out of memory) costs the data set
    nothing but time: the scheduler runs the task again, on another worker or the one
    the nanny restarted, up to ``distributed.scheduler.allowed-failures`` times (3 by
    default), then reports a ``KilledWorker`` failure for that data set alone; the
    result counts the lost workers (`BatchResult.lost_workers`). Results are released on
    the cluster as they arrive, so that a worker lost later does not run a finished data
    set again.

    Interrupted (KeyboardInterrupt, e.g. Ctrl-C), it cancels the tasks and lets the
    interrupt through; on a `local_cluster` (given or the default one), the cluster's
    closing then stops the workers at once, each finishing the output folder it is
    writing, if any: ``out`` holds complete reconstruction folders only.

    Parameters
    ----------
    datasets : sequence of str or pathlib.Path
        Data set folders (irtps or DiLiGenT layout). Relative paths are made absolute
        here, so the workers must see the client's file system under the same paths.
    out : str or pathlib.Path
        The folder to hold one reconstruction folder per data set.
    options : ReconstructOptions, optional
        How to reconstruct every data set (`irtps.model.options.ReconstructOptions`; default
        classic photometric stereo with the default settings). It travels to the workers
        as it is.
    client : distributed.Client, optional
        The cluster to run on; default a `local_cluster` for this call (whose worker
        processes re-import the calling script: call from under
        ``if __name__ == "__main__":``).
    progress : bool
        Show a progress bar, advancing as data sets finish.
    resume : bool
        Keep each output folder that is already complete, status ``"reused"``, instead
        of reconstructing it again (see `reconstruct_to_folder` for what is complete);
        without it, an existing output folder is replaced once its new reconstruction is
        written.
    exclude_images : str or mapping, optional
        Images to leave out, not read (`irtps.load_dataset`): one list for every data set,
        or a list (or None) per data set's ``NAME`` (`output_names`; a name left out leaves
        out nothing), e.g. ``{"bearPNG": "1-20"}``. A list that names none of a data set's
        images fails that data set alone.
    **settings
        Fields of `ReconstructOptions` that replace those of `options`, e.g.
        ``method="irtps"``.

    Returns
    -------
    list of BatchResult
        One per data set, in the order given.

    Raises
    ------
    ArgumentError
        Before anything runs: no data set, an option unknown or out of range
        (`irtps.model.options.OptionError`), a malformed list of images to leave out or one for
        a ``NAME`` that is none of the data sets'.
    IrtpsError
        Before anything runs: dask not installed.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.io.dataset_writer import save_dataset
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=24, lights=6, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder, local_cluster(1, processes=False) as client:
    ...     save_dataset(data, folder + "/cap")
    ...     results = reconstruct_many([folder + "/cap", folder + "/missing"], folder + "/out", client=client)
    >>> [(r.name, r.status) for r in results]
    [('cap', 'ok'), ('missing', 'failed')]
    >>> results[0].mean_angular_error < 2
    True
    """
    if not datasets:
        raise ArgumentError("datasets", "none given")
    options = ReconstructOptions.build(options, **settings)
    distributed = _import_distributed()
    from tqdm import tqdm

    sources = [str(resolve_path(path)) for path in datasets]
    folder = resolve_path(out)
    names = output_names(sources)
    exclusions = _exclusions(exclude_images, names)
    with _using(client) as active, _lost_workers(active) as lost:
        pending = {
            active.submit(
                reconstruct_to_folder,
                source,
                str(folder / name),
                options,
                resume=resume,
                exclude_images=exclusions[name],
                pure=False,
                priority=-index,
            ): (name, source)
            for index, (name, source) in enumerate(zip(names, sources, strict=True))
        }
        outcomes = {}
        try:
            with tqdm(
                distributed.as_completed(pending, loop=active.loop),
                total=len(pending),
                desc="batch",
                unit="set",
                disable=not progress,
                leave=False,
            ) as bar:
                for future in bar:
                    name, source = pending.pop(future)
                    outcomes[name] = outcome = _with_lost_workers(_result_of(future, name, source), lost[future.key])
                    del future  # released: a worker lost later does not run this data set again
                    if outcome.warnings:
                        with tqdm.external_write_mode():  # the bar steps aside for the warnings
                            _issue_warnings(outcome)
                    bar.set_postfix(failed=sum(outcome.failed for outcome in outcomes.values()))
        except BaseException:  # interrupted: run nothing more; a local cluster stops its workers as it closes
            with _quiet_logging():
                try:
                    active.cancel(list(pending))
                except Exception:  # the cluster may be gone already; the interrupt is what matters
                    pass
            raise
    return [outcomes[name] for name in names]


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
    close while it runs `reconstruct_to_folder` finishes the output folder it is writing,
    if any, and exits at once (SIGTERM does the same); the worker processes are gone when
    the ``with`` block is left. Leaving it on an exception (e.g. KeyboardInterrupt) closes
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
    distributed = _import_distributed()
    import dask  # installed with distributed

    worker_options = {"env": {"RAYON_NUM_THREADS": str(threads_per_worker)}, "preload": [__name__]} if processes else {}
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
        with _shielded(), _quiet_logging():
            _close(client, cluster)
        raise
    _close(client, cluster)


def dask_setup(worker) -> None:
    """Set up a worker process of a `local_cluster` (a Dask preload: ``--preload irtps.batch.run``).

    The process ignores SIGINT (the client process, signalled too, closes the cluster)
    and exits on SIGTERM or when closed while it runs `reconstruct_to_folder`, at once
    but never in the middle of writing an output folder, with its logs silenced; it
    creates no multiprocessing lock (for progress bars), which an abrupt exit would
    leak. Nothing is changed in a process that is not a child process (a cluster of
    threads).
    """
    if multiprocessing.parent_process() is None or threading.current_thread() is not threading.main_thread():
        return
    from tqdm import tqdm

    if "_lock" not in vars(tqdm):
        tqdm.set_lock(threading.RLock())  # instead of a multiprocessing lock, a semaphore that os._exit would leak
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda signum, frame: _TASKS.exit_after_writes())
    close = worker.close

    async def close_now(*args, **kwargs):
        logging.disable(logging.CRITICAL)  # a closing worker has nothing more to report
        if _TASKS.busy:
            _TASKS.exit_after_writes()  # not waiting for a reconstruction under way
        return await close(*args, **kwargs)

    worker.close = close_now


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
    distributed = _import_distributed()
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
        with _shielded(), _quiet_logging():
            client.close()
        raise
    client.close()


def summary_table(results: Sequence[BatchResult]) -> str:
    """The outcome of a batch as a markdown table: data set, status (with the workers
    lost while they held the data set, if any), seconds, the robust mode of its fit, mean
    angular error (when there is ground truth) and the error of a failed data set.

    Parameters
    ----------
    results : sequence of BatchResult

    Returns
    -------
    str

    Examples
    --------
    >>> print(summary_table([BatchResult("ball", "/d/ball", "ok", 1.25, metrics={"normal_mean_angular_deg": 2.5}, robust_used="tukey"),
    ...                      BatchResult("cap", "/d/cap", "failed", 0.5, error="/d/cap/scene.json: missing"),
    ...                      BatchResult("cavity", "/d/cavity", "ok", 3.0, lost_workers=1, robust_used="lobe")]), end="")
    | Data set | Status | Seconds | Robust mode | Angular error (°) | Error |
    |---|---|---|---|---|---|
    | ball | ok | 1.2 | tukey | 2.5 |  |
    | cap | failed | 0.5 | n/a | n/a | /d/cap/scene.json: missing |
    | cavity | ok (1 worker lost) | 3.0 | lobe | n/a |  |
    """
    lines = ["| Data set | Status | Seconds | Robust mode | Angular error (°) | Error |", "|---|---|---|---|---|---|"]
    for result in results:
        seconds = "n/a" if result.seconds is None else f"{result.seconds:.1f}"
        angular = "n/a" if result.mean_angular_error is None else f"{result.mean_angular_error:.4g}"
        error = (result.error or "").replace("|", "\\|").replace("\n", " ")
        status = result.status
        if result.lost_workers:
            status += f" ({result.lost_workers} worker{'s' if result.lost_workers > 1 else ''} lost)"
        lines.append(f"| {result.name} | {status} | {seconds} | {result.robust_used or 'n/a'} | {angular} | {error} |")
    return "\n".join(lines) + "\n"


def write_summary(results: Sequence[BatchResult], out: str | Path, *, settings: dict) -> None:
    """Write ``batch.json`` (settings, counts and every `BatchResult`) and ``batch.md``
    (`summary_table`) into a batch's output folder, each atomically.

    The counts: ``succeeded`` (data sets not failed, reused ones included), ``reused``
    and ``failed``.

    Parameters
    ----------
    results : sequence of BatchResult
    out : str or pathlib.Path
        The batch's output folder; created if missing.
    settings : dict
        The reconstruction settings of the batch, recorded in ``batch.json``.
    """
    folder = Path(out)
    failed = sum(result.failed for result in results)
    reused = sum(result.status == "reused" for result in results)
    summary = {
        **stamp(BATCH),
        "settings": settings,
        "succeeded": len(results) - failed,
        "reused": reused,
        "failed": failed,
        "datasets": [asdict(result) for result in results],
    }
    atomic_write_text(folder / SUMMARY_JSON, json.dumps(summary, indent=2))
    atomic_write_text(folder / SUMMARY_MARKDOWN, summary_table(results))


class _Tasks:
    """The `reconstruct_to_folder` calls of this process, and their writes under way."""

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._running = self._writing = 0
        self._exiting = False

    def __reduce__(self) -> str:
        return "_TASKS"  # this process's one instance, by reference (a task pickled by value refers to it)

    @property
    def busy(self) -> bool:
        return self._running > 0

    @contextmanager
    def running(self) -> Iterator[None]:
        with self._condition:
            self._running += 1
        try:
            yield
        finally:
            with self._condition:
                self._running -= 1

    @contextmanager
    def writing(self) -> Iterator[None]:
        with self._condition:
            if self._exiting:
                raise IrtpsError("the worker is stopping")  # never reported: the process exits
            self._writing += 1
        try:
            yield
        finally:
            with self._condition:
                self._writing -= 1
                self._condition.notify_all()

    def exit_after_writes(self) -> None:
        """End this process as soon as no output folder is being written (none is started)."""
        logging.disable(logging.CRITICAL)
        with self._condition:
            self._exiting = True
            self._condition.wait_for(lambda: self._writing == 0)
        os._exit(0)


_TASKS = _Tasks()


def _close(client, cluster) -> None:
    """Close a client, then its cluster (either may be None)."""
    try:
        if client is not None:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


@contextmanager
def _quiet_logging() -> Iterator[None]:
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


# Warnings of tasks: recorded per thread (a worker may run several tasks at once) --------

_recording = threading.local()
_recording_lock = threading.Lock()
_recording_users = 0
_recording_shown: Callable | None = None  # warnings._showwarnmsg while tasks record


@contextmanager
def _recorded_warnings() -> Iterator[list[tuple[type[Warning], str]]]:
    """The warnings raised in this thread for the duration, as (category, message) pairs,
    none shown; other threads' warnings are shown as before.

    The warnings filters are the process's (Python's are global): a warning the filters
    ignore is not recorded, and a repeated one (the same text, category and line) is
    recorded at least once. The filters' registries start afresh, so that a warning that
    an earlier task in this thread raised is recorded again. While any thread records,
    ``warnings._showwarnmsg`` (which `warnings.catch_warnings` leaves alone) is a
    dispatcher that keeps a recording thread's warnings and passes the others on.
    """
    global _recording_users, _recording_shown
    records: list[tuple[type[Warning], str]] = []
    with _recording_lock:
        if _recording_users == 0:
            _recording_shown = warnings._showwarnmsg  # type: ignore[attr-defined]
            warnings._showwarnmsg = _dispatch_warning  # type: ignore[attr-defined]
        _recording_users += 1
        warnings._filters_mutated()  # type: ignore[attr-defined]
    _recording.records = records
    try:
        yield records
    finally:
        del _recording.records
        with _recording_lock:
            _recording_users -= 1
            if _recording_users == 0:
                if warnings._showwarnmsg is _dispatch_warning:  # type: ignore[attr-defined]
                    warnings._showwarnmsg = _recording_shown  # type: ignore[attr-defined]
                _recording_shown = None


def _dispatch_warning(message: warnings.WarningMessage) -> None:
    records = getattr(_recording, "records", None)
    if records is not None:
        records.append((message.category, str(message.message)))
        return
    shown = _recording_shown or warnings._showwarnmsg  # type: ignore[attr-defined]  # None: the recording has just ended
    (warnings._showwarnmsg_impl if shown is _dispatch_warning else shown)(message)  # type: ignore[attr-defined]


def _with_warnings(outcome: BatchResult, recorded: list[tuple[type[Warning], str]]) -> BatchResult:
    """The outcome with the recorded warnings, each once."""
    if not recorded:
        return outcome
    texts = (
        message if issubclass(category, IrtpsWarning) else f"{_category_name(category)}: {message}"
        for category, message in recorded
    )
    return replace(outcome, warnings=tuple(dict.fromkeys(texts)))


def _category_name(category: type[Warning]) -> str:
    return (
        category.__qualname__ if category.__module__ == "builtins" else f"{category.__module__}.{category.__qualname__}"
    )


_CATEGORY_PREFIX = re.compile(r"([A-Za-z_][\w.]*): (.*)", re.DOTALL)


def _warning_of(text: str) -> tuple[type[Warning], str]:
    """The category and message of a `BatchResult.warnings` entry: a known category before
    ``": "`` (builtin, or from a module imported here), else an `IrtpsWarning`."""
    match = _CATEGORY_PREFIX.fullmatch(text)
    if match:
        module, _, name = match[1].rpartition(".")
        category = getattr(sys.modules.get(module) if module else builtins, name, None)
        if isinstance(category, type) and issubclass(category, Warning) and not issubclass(category, IrtpsWarning):
            return category, match[2]
    return IrtpsWarning, text


def _issue_warnings(outcome: BatchResult) -> None:
    """Issue a task's warnings here, as ``NAME: message``."""
    for text in outcome.warnings:
        category, message = _warning_of(text)
        warnings.warn(f"{outcome.name}: {message}", category, stacklevel=3)


def _result_of(future, name: str, source: str) -> BatchResult:
    """A task's `BatchResult`, or a failed one if the task did not return (every worker
    that ran it died)."""
    import dask
    from distributed import KilledWorker

    try:
        return future.result()
    except KilledWorker as error:
        # Older Dask releases do not carry the limit on the error; it is the configured one.
        allowed = getattr(error, "allowed_failures", None)
        if allowed is None:
            allowed = int(dask.config.get("distributed.scheduler.allowed-failures"))
        deaths = allowed + 1
        message = (
            f"KilledWorker: each of the {deaths} workers that ran it died (killed, e.g. out of memory); Dask gave up on it "
            f"(distributed.scheduler.allowed-failures = {allowed})"
        )
        return BatchResult(name, source, "failed", None, error=message, lost_workers=deaths)
    except Exception as error:  # cancelled task, unreachable cluster: the data set failed, the batch goes on
        return BatchResult(name, source, "failed", None, error=_describe(error))


def _with_lost_workers(outcome: BatchResult, lost: int) -> BatchResult:
    """The outcome with the workers lost while they held its task, as the scheduler reported them."""
    return outcome if lost <= outcome.lost_workers else replace(outcome, lost_workers=lost)


@contextmanager
def _lost_workers(client) -> Iterator[Counter]:
    """For the duration: how many times a worker that held each task (by key) left the
    cluster unexpectedly (died), from the scheduler's ``remove-worker`` events."""
    lost: Counter = Counter()

    def count(event) -> None:
        _, message = event
        if message.get("action") == "remove-worker" and not message.get("expected"):
            lost.update(message.get("processing-tasks", ()))

    client.subscribe_topic("all", count)
    try:
        yield lost
    finally:
        client.unsubscribe_topic("all")


def _complete_output(
    destination: str, source: str, options: ReconstructOptions, exclude_images: str | None
) -> tuple | None:
    """The normals, albedo, height and mask of a complete output folder of `source` made
    with `options`, leaving out the images of `exclude_images` (see `reconstruct_to_folder`),
    and its recorded robust mode, or None."""
    folder = Path(destination)
    try:
        record = load_run_record(folder)
        maps = load_reconstruction(folder)
        meshes = all(_nonempty_file(folder / name) for name in ("mesh.ply", "mesh.obj"))
        indirect = not record.get("chosen_pass") or _complete_indirect(folder / "indirect", record.get("images", []))
        excluded = select_images(dataset_image_names(source), exclude_images, where=source).excluded
    except (IrtpsError, OSError):
        return None
    same_run = (
        record["source"] == str(resolve_path(source))
        and _same_options(record["parameters"], options)
        and tuple(record.get("excluded_images", ())) == excluded
    )
    return (maps, record.get("robust_used")) if same_run and meshes and indirect else None


def _complete_indirect(folder: Path, images: list[str]) -> bool:
    """Whether a folder holds one file for each image fitted (`indirect_file_names`; images
    numbered from ``000.exr`` where ``run.json`` does not list them) and nothing else, none
    empty."""
    files = {file.name: file for file in folder.iterdir()}
    expected = indirect_file_names(images, len(images) if images else len(files))
    return bool(files) and files.keys() == set(expected) and all(map(_nonempty_file, files.values()))


def _nonempty_file(path: Path) -> bool:
    return path.is_file() and path.stat().st_size > 0


def _same_options(recorded: dict, options: ReconstructOptions) -> bool:
    """Whether a ``run.json``'s parameters are `options`; an option left unset (None),
    which the reconstruction resolves for each data set, matches any recorded value."""
    wanted = json.loads(json.dumps(options.to_dict()))
    return recorded.keys() == wanted.keys() and all(
        value is None or recorded[key] == value for key, value in wanted.items()
    )


def _exclusions(exclude_images: str | Mapping[str, str | None] | None, names: list[str]) -> dict[str, str | None]:
    """Each data set's list of images to leave out (`reconstruct_many`'s ``exclude_images``),
    each list checked for form."""
    if exclude_images is None or isinstance(exclude_images, str):
        if exclude_images is not None:
            parse_image_list(exclude_images)
        return dict.fromkeys(names, exclude_images)
    if not isinstance(exclude_images, Mapping):
        raise ArgumentError(
            "exclude_images",
            f"expected a list of images or a mapping of data set names to lists, got {type(exclude_images).__name__}",
        )
    unknown = sorted(set(exclude_images) - set(names), key=str)
    if unknown:
        raise ArgumentError("exclude_images", f"{unknown[0]!r} is none of the data sets ({', '.join(names)})")
    for images in exclude_images.values():
        if images is not None:
            parse_image_list(images)
    return {name: exclude_images.get(name) for name in names}


def _describe(error: BaseException) -> str:
    """An error's message; the exception type too when it is not one irtps raises on purpose."""
    return str(error) if isinstance(error, IrtpsError) else f"{type(error).__name__}: {error}"


@contextmanager
def _using(client) -> Iterator:
    """The given client, or a `local_cluster` for the duration."""
    if client is not None:
        yield client
        return
    with local_cluster() as local:
        yield local


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise IrtpsError(f"batch runs need Dask (dask.distributed), which is not installed: {INSTALL_HINT}") from None
    return distributed
