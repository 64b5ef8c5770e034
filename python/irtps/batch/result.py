"""What became of one data set of a batch (`BatchResult`)."""

from __future__ import annotations

from dataclasses import dataclass

from irtps.errors import IrtpsError

__all__ = ["BatchResult", "describe_error"]


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


def describe_error(error: BaseException) -> str:
    """An error's message; the exception type too when it is not one irtps raises on purpose."""
    return str(error) if isinstance(error, IrtpsError) else f"{type(error).__name__}: {error}"
