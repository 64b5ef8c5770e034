"""Memory: refuse up front the inputs that would need more of it than the machine has, and
give freed memory back.

`check_memory` is called where the size of a large allocation is known before it is made
(the images of a data set, the planes of a rendering), so that an input too large for
the machine is a clear error naming the field instead of a crash, an exhausted swap or
the out-of-memory killer. `return_freed_memory` keeps a run's resident memory near what it
holds (the ``irtps`` command calls it).
"""

from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

from irtps.errors import IrtpsError

#: glibc's ``mallopt`` parameter: the size from which a block is mapped on its own.
_M_MMAP_THRESHOLD = -3
#: glibc's initial value of that threshold, kept fixed by `return_freed_memory`.
MMAP_THRESHOLD_BYTES = 128 * 1024
_MEMINFO = Path("/proc/meminfo")
_CGROUP_V2 = Path("/sys/fs/cgroup")
_CGROUP_V1 = Path("/sys/fs/cgroup/memory")
_STATUS = Path("/proc/self/status")


def available_memory_bytes() -> int | None:
    """The memory this process can still allocate without swapping, in bytes, if known.

    On Linux ``MemAvailable`` of ``/proc/meminfo``, lowered to what is left under the
    process's control-group limit (a container's memory limit) when there is one, and to
    what is left of its address-space limit (``RLIMIT_AS``, ``ulimit -v``: the limit less
    the ``VmSize`` of ``/proc/self/status``) when there is one; elsewhere the free physical
    pages (``os.sysconf``). None when none of these can be read.

    Returns
    -------
    int or None
    """
    available = _meminfo_available()
    if available is None:
        available = _sysconf_available()
    for left in (_cgroup_left(), _address_space_left()):
        if left is not None:
            available = left if available is None else min(available, left)
    return available


def return_freed_memory() -> bool:
    """Have the C library give each large freed block back to the system at once (glibc).

    glibc maps every block above a threshold on its own and unmaps it when it is freed, but
    raises the threshold to the size of each such block freed (up to 32 MiB): from then on,
    image-sized temporaries come from the heap and stay resident after they are freed, which
    raised classic photometric stereo's peak resident memory on DiLiGenT reading
    (docs/benchmarks.md, IRT-PS cost). This fixes the threshold at its initial 128 KiB.

    Returns
    -------
    bool
        Whether the threshold was set (False where the C library has no ``mallopt``).
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))


def format_bytes(count: float) -> str:
    """A byte count in decimal units, e.g. ``"41.2 GB"``.

    Examples
    --------
    >>> format_bytes(41_200_000_000), format_bytes(512), format_bytes(1.5e15)
    ('41.2 GB', '512 B', '1.5 PB')
    """
    if count < 1000:
        return f"{int(count)} B"
    for unit in ("kB", "MB", "GB", "TB", "PB", "EB"):
        count /= 1000
        if count < 999.95 or unit == "EB":
            return f"{count:.1f} {unit}"
    raise AssertionError("unreachable")


def check_memory(nbytes: int, what: str) -> None:
    """Raise `IrtpsError` if ``nbytes`` is more than the memory available.

    Nothing is checked when the available memory is unknown.

    Parameters
    ----------
    nbytes : int
        The memory an allocation about to be made needs.
    what : str
        The field or file and what it asks for, the start of the message, e.g.
        ``"lights: 100000000 lights of 96x96 images"``.

    Raises
    ------
    IrtpsError
        ``"WHAT need 41.2 GB, more than the 20.1 GB available"``.
    """
    available = available_memory_bytes()
    if available is not None and nbytes > available:
        raise IrtpsError(f"{what} need {format_bytes(nbytes)}, more than the {format_bytes(available)} available")


def _meminfo_available() -> int | None:
    try:
        text = _MEMINFO.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        name, _, value = line.partition(":")
        if name == "MemAvailable":
            fields = value.split()
            try:
                return int(fields[0]) * (1024 if fields[1:] == ["kB"] else 1)
            except (ValueError, IndexError):
                return None
    return None


def _sysconf_available() -> int | None:
    try:
        pages, page_size = os.sysconf("SC_AVPHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None
    return pages * page_size if pages > 0 and page_size > 0 else None


def _cgroup_left() -> int | None:
    """The memory left under this process's cgroup limit (v2, else v1), if there is a limit."""
    for folder, limit_name, usage_name, cache_name in (
        (_CGROUP_V2, "memory.max", "memory.current", "inactive_file"),
        (_CGROUP_V1, "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"),
    ):
        try:
            limit_text = (folder / limit_name).read_text().strip()
            usage = int((folder / usage_name).read_text().strip())
        except (OSError, ValueError):
            continue
        usage -= _stat_field(folder / "memory.stat", cache_name)  # page cache the kernel can drop
        if limit_text == "max":
            return None
        try:
            limit = int(limit_text)
        except ValueError:
            return None
        if limit >= 1 << 60:  # cgroup v1 writes a huge number for "no limit"
            return None
        return max(0, limit - usage)
    return None


def _address_space_left() -> int | None:
    """What is left of the process's address-space limit (soft ``RLIMIT_AS``), if there is one.

    The limit counts every mapping, touched or not (thread stacks, the C library's arenas,
    reserved buffers), as ``VmSize`` does.
    """
    try:
        import resource
    except ImportError:  # not on Unix
        return None
    try:
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (AttributeError, ValueError, OSError):
        return None
    if limit == resource.RLIM_INFINITY or limit < 0 or not sys.platform.startswith("linux"):
        return None
    try:
        for line in _STATUS.read_text().splitlines():
            name, _, value = line.partition(":")
            if name == "VmSize":
                return max(0, limit - int(value.split()[0]) * 1024)
    except (OSError, ValueError, IndexError):
        return None
    return None


def _stat_field(path: Path, name: str) -> int:
    try:
        for line in path.read_text().splitlines():
            key, _, value = line.partition(" ")
            if key == name:
                return int(value)
    except (OSError, ValueError):
        pass
    return 0
