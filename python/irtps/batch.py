"""Batch runs: reconstruct many data sets on a Dask cluster, one task per data set.

A task receives a data set's *path* and its output folder's path: the worker reads the
data set and writes the reconstruction itself, atomically, so the workers must see the
same file system as the client, under the same paths. A data set that fails is reported
with its error and the others go on.

Dask (``dask.distributed``) is an optional dependency: ``pip install 'irtps[batch]'``.
"""

from __future__ import annotations

import inspect
import json
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from irtps.atomic import atomic_write_text
from irtps.errors import IrtpsError
from irtps.evaluate import evaluate
from irtps.reconstruct import METHODS, load_and_reconstruct, reconstruct, save_reconstruction

__all__ = ["BatchResult", "connect", "local_cluster", "output_names", "reconstruct_many", "reconstruct_to_folder", "summary_table", "write_summary"]

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
        ``"ok"`` or ``"failed"``.
    seconds : float or None
        Time spent on the worker (reading, reconstructing, writing, evaluating); None
        when the task did not report back (e.g. its worker died).
    error : str or None
        Why it failed: the error message, which names the file or field concerned.
    metrics : dict or None
        The errors against the data set's ground truth (`irtps.evaluate.Metrics.to_dict`);
        None without ground truth or on failure.
    """

    name: str
    source: str
    status: str
    seconds: float | None
    error: str | None = None
    metrics: dict | None = None

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
        base = Path(path).resolve().name
        name, suffix = base, 2
        while name in taken:
            name, suffix = f"{base}-{suffix}", suffix + 1
        taken.add(name)
        names.append(name)
    return names


def reconstruct_to_folder(source: str, destination: str, options: dict) -> BatchResult:
    """Reconstruct one data set folder into an output folder: the task of a batch.

    Errors are caught and reported, never raised, so that one bad data set does not
    stop a batch.

    Parameters
    ----------
    source : str
        The data set folder.
    destination : str
        The reconstruction folder to write (atomically, as `irtps.save_reconstruction`).
    options : dict
        Keyword arguments of `irtps.reconstruct` (``method`` included).

    Returns
    -------
    BatchResult
        Named after ``destination``'s last part.

    Examples
    --------
    >>> outcome = reconstruct_to_folder("no/such/folder", "out/folder", {"method": "ps"})
    >>> outcome.status, outcome.error
    ('failed', 'no/such/folder: no such data set folder')
    """
    name = Path(destination).name
    start = time.perf_counter()
    try:
        dataset, result = load_and_reconstruct(source, **options)
        save_reconstruction(result, destination, source=str(Path(source).resolve()))
        metrics = None
        if dataset.gt is not None:
            metrics = evaluate(mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=dataset.gt).to_dict()
    except Exception as error:  # a batch reports every failure of a data set and goes on
        return BatchResult(name, source, "failed", time.perf_counter() - start, error=_describe(error))
    return BatchResult(name, source, "ok", time.perf_counter() - start, metrics=metrics)


def reconstruct_many(
    datasets: Sequence[str | Path],
    out: str | Path,
    *,
    method: str = "ps",
    client=None,
    progress: bool = False,
    **options,
) -> list[BatchResult]:
    """Reconstruct many data set folders on a Dask cluster, each into ``out/NAME/``.

    Each data set is one task; the worker reads the folder and writes
    ``out/NAME/`` (as `irtps.save_reconstruction`, atomically) itself, with ``NAME``
    from `output_names`. A failed data set is reported in its `BatchResult`; the others
    go on. Nothing is written for a failed data set: an output from an earlier run
    stays as it was.

    Parameters
    ----------
    datasets : sequence of str or pathlib.Path
        Data set folders (irtps or DiLiGenT layout). Relative paths are made absolute
        here, so the workers must see the client's file system under the same paths.
    out : str or pathlib.Path
        The folder to hold one reconstruction folder per data set.
    method : str
        As for `irtps.reconstruct`.
    client : distributed.Client, optional
        The cluster to run on; default a `local_cluster` for this call (whose worker
        processes re-import the calling script: call from under
        ``if __name__ == "__main__":``).
    progress : bool
        Show a progress bar, advancing as data sets finish.
    **options
        The other keyword arguments of `irtps.reconstruct` (not ``progress``).

    Returns
    -------
    list of BatchResult
        One per data set, in the order given.

    Raises
    ------
    IrtpsError
        Before anything runs: no data set, an unknown method or option, or dask not
        installed.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.dataset import save_dataset
    >>> from irtps.synth import synthesize
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
        raise IrtpsError("datasets: none given")
    _check_options(method, options)
    distributed = _import_distributed()
    from tqdm import tqdm

    sources = [str(Path(path).resolve()) for path in datasets]
    folder = Path(out).resolve()
    names = output_names(sources)
    with _using(client) as active:
        pending = {
            active.submit(reconstruct_to_folder, source, str(folder / name), {"method": method, **options}, pure=False): (name, source)
            for name, source in zip(names, sources, strict=True)
        }
        outcomes = {}
        with tqdm(distributed.as_completed(pending), total=len(pending), desc="batch", unit="set", disable=not progress, leave=False) as bar:
            for future in bar:
                name, source = pending[future]
                outcomes[name] = _result_of(future, name, source)
                bar.set_postfix(failed=sum(outcome.failed for outcome in outcomes.values()))
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

    Yields
    ------
    distributed.Client

    Raises
    ------
    IrtpsError
        If ``workers`` or ``threads_per_worker`` is below 1, or dask is not installed.

    Examples
    --------
    >>> with local_cluster(2, processes=False) as client:
    ...     len(client.scheduler_info()["workers"])
    2
    """
    if workers is not None and workers < 1:
        raise IrtpsError(f"workers: must be at least 1, not {workers}")
    if threads_per_worker < 1:
        raise IrtpsError(f"threads_per_worker: must be at least 1, not {threads_per_worker}")
    distributed = _import_distributed()
    worker_options = {"env": {"RAYON_NUM_THREADS": str(threads_per_worker)}} if processes else {}
    with (
        distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=processes, dashboard_address=None, **worker_options) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield client


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
    try:
        client = distributed.Client(address)
    except (OSError, ValueError) as error:
        raise IrtpsError(f"{address}: cannot reach a Dask scheduler there ({error})") from None
    with client:
        yield client


def summary_table(results: Sequence[BatchResult]) -> str:
    """The outcome of a batch as a markdown table: data set, status, seconds, mean
    angular error (when there is ground truth) and the error of a failed data set.

    Parameters
    ----------
    results : sequence of BatchResult

    Returns
    -------
    str

    Examples
    --------
    >>> print(summary_table([BatchResult("ball", "/d/ball", "ok", 1.25, metrics={"normal_mean_angular_deg": 2.5}),
    ...                      BatchResult("cap", "/d/cap", "failed", 0.5, error="/d/cap/scene.json: missing")]), end="")
    | Data set | Status | Seconds | Angular error (°) | Error |
    |---|---|---|---|---|
    | ball | ok | 1.2 | 2.5 |  |
    | cap | failed | 0.5 | n/a | /d/cap/scene.json: missing |
    """
    lines = ["| Data set | Status | Seconds | Angular error (°) | Error |", "|---|---|---|---|---|"]
    for result in results:
        seconds = "n/a" if result.seconds is None else f"{result.seconds:.1f}"
        angular = "n/a" if result.mean_angular_error is None else f"{result.mean_angular_error:.4g}"
        error = (result.error or "").replace("|", "\\|").replace("\n", " ")
        lines.append(f"| {result.name} | {result.status} | {seconds} | {angular} | {error} |")
    return "\n".join(lines) + "\n"


def write_summary(results: Sequence[BatchResult], out: str | Path, *, settings: dict) -> None:
    """Write ``batch.json`` (settings, counts and every `BatchResult`) and ``batch.md``
    (`summary_table`) into a batch's output folder, each atomically.

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
    summary = {"settings": settings, "succeeded": len(results) - failed, "failed": failed, "datasets": [asdict(result) for result in results]}
    atomic_write_text(folder / SUMMARY_JSON, json.dumps(summary, indent=2))
    atomic_write_text(folder / SUMMARY_MARKDOWN, summary_table(results))


def _check_options(method: str, options: dict) -> None:
    """Raise `IrtpsError` for what would fail every task: an unknown method or option."""
    if method not in METHODS:
        raise IrtpsError(f"method: unknown {method!r} (choose from {', '.join(METHODS)})")
    if "progress" in options:
        raise IrtpsError("progress: workers show no progress bar; use reconstruct_many(progress=...)")
    try:
        inspect.signature(reconstruct).bind(None, method, **options)
    except TypeError as error:
        raise IrtpsError(f"options: {error}") from None


def _result_of(future, name: str, source: str) -> BatchResult:
    """A task's `BatchResult`, or a failed one if the task did not return (its worker died)."""
    try:
        return future.result()
    except Exception as error:  # lost worker, cancelled task: the data set failed, the batch goes on
        return BatchResult(name, source, "failed", None, error=_describe(error))


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
