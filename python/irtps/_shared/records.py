"""The records by which a folder is known for an output of irtps, which a later run may replace.

Each kind of output folder holds one record, written with the output: a JSON file whose
``"format"`` field names the kind and its version, beside the version of irtps that wrote
it, or for a report a marker in the head of its page:

- ``run.json``, format ``irtps.run/1``: a reconstruction (``irtps reconstruct``, and each
  data set of ``irtps batch``, ``irtps table`` and ``irtps demo``);
- ``table.json``, ``irtps.table/1``: a comparison table (``irtps table``, ``irtps demo``);
- ``batch.json``, ``irtps.batch/1``: a batch's folder (``irtps batch``);
- ``gt/rendering.json``, ``irtps.rendering/1``: a data set that irtps rendered (``irtps render``,
  ``irtps synth``);
- ``index.html``, ``irtps.report/1``: a report (``irtps report``).

A file of that name alone (a web site's ``index.html``, another tool's ``run.json``) does not
make a folder ours: `written_by_irtps` reads the record and checks its format.
"""

from __future__ import annotations

import os
import stat
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from irtps.errors import IrtpsError
from irtps._shared.guarded import parse_json

__all__ = [
    "BATCH",
    "CALIBRATION",
    "RENDERING",
    "REPORT",
    "REPORT_MARKER",
    "RUN",
    "TABLE",
    "irtps_version",
    "stamp",
    "written_by_irtps",
]

RUN = "irtps.run/1"
TABLE = "irtps.table/1"
BATCH = "irtps.batch/1"
RENDERING = "irtps.rendering/1"
REPORT = "irtps.report/1"
CALIBRATION = "irtps.calibration/1"

#: The record of each kind of output folder: its path inside the folder, and its format.
RECORDS = {
    "run.json": RUN,
    "table.json": TABLE,
    "batch.json": BATCH,
    "gt/rendering.json": RENDERING,
    "index.html": REPORT,
    "calibration.json": CALIBRATION,
}

#: The line in the head of a report's page that marks it as ours.
REPORT_MARKER = f'<meta name="irtps-format" content="{REPORT}">'

#: How much of a record is read to recognise it: the marker of a page is in its head, and a
#: JSON record of ours is far smaller (a batch of 10,000 data sets takes 5 MB).
_RECORD_BYTES = {REPORT: 4096}
_JSON_RECORD_BYTES = 64 * 1024 * 1024


def irtps_version() -> str:
    """The version of irtps installed (``"0+unknown"`` when it is run from a source tree)."""
    try:
        return version("irtps")
    except PackageNotFoundError:
        return "0+unknown"


def stamp(kind: str) -> dict[str, str]:
    """The fields that open a JSON record of kind `kind`: its format and the irtps version.

    Examples
    --------
    >>> sorted(stamp(RUN))
    ['format', 'irtps']
    >>> stamp(RUN)["format"]
    'irtps.run/1'
    """
    if kind not in RECORDS.values() or kind == REPORT:
        raise ValueError(f"no JSON record of kind {kind!r}")
    return {"format": kind, "irtps": irtps_version()}


def written_by_irtps(folder: str | Path) -> bool:
    """Whether a folder is an output of irtps, which a later run may replace.

    It is when it holds one of the records (see the module's table) as a regular file (not
    a symbolic link), whose format is that record's: a JSON object whose ``"format"`` field
    is it, or a page whose head holds `REPORT_MARKER`.

    Parameters
    ----------
    folder : str or pathlib.Path

    Returns
    -------
    bool

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     _ = (Path(folder) / "run.json").write_text('{"seed": 3}')
    ...     print(written_by_irtps(folder))
    ...     _ = (Path(folder) / "run.json").write_text('{"format": "irtps.run/1"}')
    ...     print(written_by_irtps(folder))
    False
    True
    """
    return any(_is_record(Path(folder) / name, kind) for name, kind in RECORDS.items())


def _is_record(path: Path, kind: str) -> bool:
    data = _head(path, _RECORD_BYTES.get(kind, _JSON_RECORD_BYTES))
    if data is None:
        return False
    if kind == REPORT:
        return REPORT_MARKER.encode() in data
    try:
        record = parse_json(data.decode("utf-8"), str(path), error=IrtpsError)
    except (IrtpsError, UnicodeDecodeError):
        return False
    return isinstance(record, dict) and record.get("format") == kind


def _head(path: Path, size: int) -> bytes | None:
    """The first `size` bytes of a regular file (not a link, never a FIFO); None for anything
    else, or a JSON record larger than `size`."""
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        with open(path, "rb") as handle:
            data = handle.read(size + 1)
    except (OSError, ValueError):
        return None
    if len(data) > size and size == _JSON_RECORD_BYTES:
        return None
    return data[:size]
