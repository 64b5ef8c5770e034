"""The task of a batch, run on a worker: reconstruct one data set folder into its output
folder (`reconstruct_to_folder`), and the set-up of a local cluster's worker processes
(`dask_setup`), which stop between output folders, never in the middle of writing one."""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from irtps._shared.paths import resolve_path
from irtps.batch.result import BatchResult, describe_error
from irtps.batch.resume import complete_output
from irtps.batch.task_warnings import recorded_warnings, with_warnings
from irtps.errors import IrtpsError
from irtps.io.dataset import load_ground_truth
from irtps.irt.folder import save_reconstruction
from irtps.irt.reconstruct import load_and_reconstruct
from irtps.model.metrics import evaluate
from irtps.model.options import ReconstructOptions

__all__ = ["dask_setup", "reconstruct_to_folder"]


def reconstruct_to_folder(
    source: str,
    destination: str,
    options: ReconstructOptions,
    *,
    resume: bool = False,
    exclude_images: str | None = None,
    intrinsics: str | None = None,
    normal_map: str = "opengl",
    encoding: str | None = None,
    lights: str | None = None,
) -> BatchResult:
    """Reconstruct one data set folder into an output folder: the task of a batch.

    Errors are caught and reported, never raised, so that one bad data set does not
    stop a batch; warnings are recorded in the result (`BatchResult.warnings`), not
    shown.

    With ``resume``, an output folder that is already complete is kept as it is (and
    evaluated against the ground truth, if any): its ``run.json``, written last by
    `irtps.save_reconstruction`, is valid and records the same data set folder and the
    same options (an option left unset, resolved for each data set, matches any value)
    and left out the images that `exclude_images` names, no other, with the intrinsics file
    `intrinsics` (or none) and the camera it gives now, and the light position file `lights`
    (or none) as it and the intensities beside it read now; its normal, albedo and
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
    intrinsics : str, optional
        A ``K.txt`` that gives the data set a perspective camera (`irtps.load_dataset`).
    normal_map : {"opengl", "directx"}
        The convention of ``normal.png`` (`irtps.save_reconstruction`).
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light (`irtps.load_dataset`).
    lights : str, optional
        A light position file (``*.lp``) kept outside the data set folder, which gives a
        folder of images its lights (`irtps.load_dataset`).

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
    with _TASKS.running(), recorded_warnings() as recorded:
        try:
            kept = (
                complete_output(
                    destination, source, options, exclude_images, intrinsics, normal_map, encoding, lights=lights
                )
                if resume
                else None
            )
            if kept is None:
                status = "ok"
                dataset, result = load_and_reconstruct(
                    source,
                    options=options,
                    exclude_images=exclude_images,
                    intrinsics=intrinsics,
                    encoding=encoding,
                    lights=lights,
                )
                with _TASKS.writing():
                    save_reconstruction(
                        result,
                        destination,
                        source=str(resolve_path(source)),
                        intrinsics=intrinsics,
                        normal_map=normal_map,
                        encoding=encoding,
                        lights=lights,
                    )
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
                gt = load_ground_truth(source, mask.shape, lights=lights)
            metrics = (
                None
                if gt is None
                else evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=gt).to_dict()
            )
        except Exception as error:  # a batch reports every failure of a data set and goes on
            outcome = BatchResult(name, source, "failed", time.perf_counter() - start, error=describe_error(error))
        else:
            outcome = BatchResult(
                name, source, status, time.perf_counter() - start, metrics=metrics, robust_used=robust_used
            )
    return with_warnings(outcome, recorded)


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


def dask_setup(worker) -> None:
    """Set up a worker process of a local cluster (`irtps.batch.cluster.local_cluster`; a Dask
    preload: ``--preload irtps.batch.task``).

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
