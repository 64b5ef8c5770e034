"""The warnings of batch tasks: recorded per thread while a task runs (a worker may run
several tasks at once), carried back in its `BatchResult` and issued again on the client."""

from __future__ import annotations

import builtins
import re
import sys
import threading
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace

from irtps.batch.result import BatchResult
from irtps.errors import IrtpsWarning

__all__ = ["issue_warnings", "recorded_warnings", "with_warnings"]

_recording = threading.local()
_recording_lock = threading.Lock()
_recording_users = 0
_recording_shown: Callable | None = None  # warnings._showwarnmsg while tasks record


@contextmanager
def recorded_warnings() -> Iterator[list[tuple[type[Warning], str]]]:
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


def with_warnings(outcome: BatchResult, recorded: list[tuple[type[Warning], str]]) -> BatchResult:
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


def issue_warnings(outcome: BatchResult) -> None:
    """Issue a task's warnings here, as ``NAME: message``."""
    for text in outcome.warnings:
        category, message = _warning_of(text)
        warnings.warn(f"{outcome.name}: {message}", category, stacklevel=3)
