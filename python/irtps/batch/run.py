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

from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

from irtps._shared.paths import resolve_path
from irtps.batch.cluster import import_distributed, local_cluster, quiet_logging
from irtps.batch.plan import dataset_exclusions, dataset_intrinsics, dataset_lights, output_names
from irtps.batch.result import BatchResult, describe_error
from irtps.batch.task import reconstruct_to_folder
from irtps.batch.task_warnings import issue_warnings
from irtps.errors import ArgumentError
from irtps.io.exchange import NORMAL_MAP_CONVENTIONS
from irtps.io.imageio import ENCODINGS
from irtps.model.options import ReconstructOptions

__all__ = ["reconstruct_many"]


def reconstruct_many(
    datasets: Sequence[str | Path],
    out: str | Path,
    options: ReconstructOptions | None = None,
    *,
    client=None,
    progress: bool = False,
    resume: bool = False,
    exclude_images: str | Mapping[str, str | None] | None = None,
    intrinsics: str | Path | Mapping[str, str | Path | None] | None = None,
    normal_map: str = "opengl",
    encoding: str | None = None,
    lights: str | Path | Mapping[str, str | Path | None] | None = None,
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
        Data set folders (irtps, DiLiGenT or RTI layout, or folders of images given
        `lights`). Relative paths are made absolute here, so the workers must see the
        client's file system under the same paths.
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
    intrinsics : str, pathlib.Path or mapping, optional
        A ``K.txt`` that gives the data sets a perspective camera (`irtps.load_dataset`): one
        for every data set, or one (or None) per ``NAME``, e.g. ``{"readingPNG":
        "reading/K.txt"}``. Each file is read and checked here, before anything runs; one
        whose principal point does not fit a data set's images fails that data set alone.
        Recorded in each ``run.json``, which `resume` compares.
    normal_map : {"opengl", "directx"}
        The convention of each ``normal.png`` (`irtps.save_reconstruction`), which `resume`
        compares.
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light (`irtps.load_dataset`), which `resume` compares.
    lights : str, pathlib.Path or mapping, optional
        A light position file (``*.lp``, as ``irtps calibrate`` writes it) that gives folders
        of images their lights (`irtps.load_dataset`): one for every data set, or one (or
        None) per ``NAME``. Each file, and the ``light_intensities.txt`` beside it, is read
        here, before anything runs; one that does not list a data set's images, or given to
        a data set whose lights are its own, fails that data set alone. Recorded in each
        ``run.json`` with a digest of both files, which `resume` compares.
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
        a ``NAME`` that is none of the data sets', intrinsics or lights for a ``NAME`` that is
        none of them, a `normal_map` that is neither convention, an unknown `encoding`.
    DatasetError
        Before anything runs: an intrinsics file that is missing or not a 3x3 intrinsic
        matrix (`irtps.io.intrinsics.read_intrinsics`), a light position file or its
        intensities that cannot be read.
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
    if normal_map not in NORMAL_MAP_CONVENTIONS:
        raise ArgumentError("normal_map", f"{normal_map!r} is not one of {', '.join(NORMAL_MAP_CONVENTIONS)}")
    if encoding is not None and encoding not in ENCODINGS:
        raise ArgumentError("encoding", f"{encoding!r} is not one of {', '.join(ENCODINGS)}")
    distributed = import_distributed()
    from tqdm import tqdm

    sources = [str(resolve_path(path)) for path in datasets]
    folder = resolve_path(out)
    names = output_names(sources)
    exclusions = dataset_exclusions(exclude_images, names)
    cameras = dataset_intrinsics(intrinsics, names)
    light_files = dataset_lights(lights, names)
    with _using(client) as active, _lost_workers(active) as lost:
        pending = {
            active.submit(
                reconstruct_to_folder,
                source,
                str(folder / name),
                options,
                resume=resume,
                exclude_images=exclusions[name],
                intrinsics=cameras[name],
                normal_map=normal_map,
                encoding=encoding,
                lights=light_files[name],
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
                            issue_warnings(outcome)
                    bar.set_postfix(failed=sum(outcome.failed for outcome in outcomes.values()))
        except BaseException:  # interrupted: run nothing more; a local cluster stops its workers as it closes
            with quiet_logging():
                try:
                    active.cancel(list(pending))
                except Exception:  # the cluster may be gone already; the interrupt is what matters
                    pass
            raise
    return [outcomes[name] for name in names]


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
        return BatchResult(name, source, "failed", None, error=describe_error(error))


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


@contextmanager
def _using(client) -> Iterator:
    """The given client, or a `local_cluster` for the duration."""
    if client is not None:
        yield client
        return
    with local_cluster() as local:
        yield local
