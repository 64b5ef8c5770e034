"""Inputs that need more memory than the machine has, refused up front through the command.

The refusal names the field or folder, comes before the large allocation (the images of
a data set are not decoded, the lights of a synthetic scene are not made), and ends with
exit status 2 and one line ``irtps: error: ...``. The available memory is made small by
replacing `irtps._shared.resources.available_memory_bytes`, except for the 10^8 lights of
``irtps synth``, which no machine holds.
"""

import platform
import re
import resource
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import irtps.io.diligent
import irtps._shared.resources
import pytest
from irtps.cli.main import main
from irtps._shared.resources import return_freed_memory
from irtps.errors import IrtpsError
from irtps._shared.resources import available_memory_bytes, check_memory, format_bytes

from cli_helpers import refused

DATA = Path(__file__).parent / "data"
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # 96x96, 3 lights, EXR
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 48x44, 8 lights, 16-bit PNG


@pytest.fixture
def memory(monkeypatch):
    """Set the memory the checks see as available, in bytes."""

    def set_available(nbytes):
        monkeypatch.setattr(irtps._shared.resources, "available_memory_bytes", lambda: nbytes)

    return set_available


@pytest.fixture
def no_decoding(monkeypatch):
    """Fail the test if a data set's images are decoded."""

    def decode(paths):
        raise AssertionError(f"decoded {len(paths)} images before checking the memory")

    monkeypatch.setattr(sys.modules["irtps.io.dataset"], "read_images", decode)
    monkeypatch.setattr(sys.modules["irtps.io.diligent"], "read_images", decode)


def _snapshot(folder):
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _claim_exr_size(path, width, height):
    """Rewrite the data window of an EXR header to claim width x height pixels."""
    data = bytearray(path.read_bytes())
    window = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    data[window + 8 : window + 16] = struct.pack("<ii", width - 1, height - 1)
    path.write_bytes(bytes(data))


# Data sets: checked from the first image's header and the image count ----------------------


@pytest.mark.parametrize("command", ["reconstruct", "table"])
def test_a_data_set_whose_images_do_not_fit_is_refused_before_decoding(command, memory, no_decoding, tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    before = _snapshot(tmp_path)
    memory(300_000)  # the 3 images of 96x96 float32 RGB take 331 776 bytes
    argv = (
        ["table", str(data), "--quiet"]
        if command == "table"
        else [command, str(data), "--out", str(tmp_path / "out"), "--quiet"]
    )
    err = refused(argv, capsys)
    assert err == (
        f"irtps: error: {data / 'images'}: 3 images of 96x96 decoded as float32 RGB need 331.8 kB, more than the 300.0 kB available\n"
    )
    assert _snapshot(tmp_path) == before


def test_a_diligent_data_set_whose_images_do_not_fit_is_refused_before_decoding(memory, no_decoding, tmp_path, capsys):
    data = shutil.copytree(BALL, tmp_path / "ball")
    before = _snapshot(tmp_path)
    memory(200_000)  # 8 images of 48x44: 202 752 bytes
    err = refused(["reconstruct", str(data), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert (
        err
        == f"irtps: error: {data / 'filenames.txt'}: 8 images of 48x44 decoded as float32 RGB need 202.8 kB, more than the 200.0 kB available\n"
    )
    assert _snapshot(tmp_path) == before


def test_an_image_header_claiming_a_huge_size_is_sized_before_decoding(memory, no_decoding, tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    _claim_exr_size(data / "images" / "000.exr", 10_000, 10_000)
    memory(10**9)
    err = refused(["reconstruct", str(data), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert err == (
        f"irtps: error: {data / 'images'}: 3 images of 10000x10000 decoded as float32 RGB need 3.6 GB, more than the 1.0 GB available\n"
    )


def test_a_data_set_that_fits_is_read(memory, tmp_path, capsys):
    memory(400_000)
    assert main(["reconstruct", str(MITSUBA), "--out", str(tmp_path / "out"), "--quiet"]) == 0


# Rendering: checked before the renderer or any image is made -------------------------------


def test_rendering_a_data_set_that_does_not_fit_is_refused(memory, tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    before = _snapshot(tmp_path)
    memory(1_000_000)  # direct + 4 bounces + their sums: 7 x 3 x 96 x 96 x 12 bytes
    err = refused(["render", str(data), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert err == (
        "irtps: error: lights: 3 lights of 96x96 images (direct light, 4 bounces and their sums, float32 RGB) "
        "need 2.3 MB, more than the 1.0 MB available\n"
    )
    assert _snapshot(tmp_path) == before


def test_a_synthetic_scene_that_does_not_fit_is_refused(memory, tmp_path, capsys):
    memory(10_000)
    err = refused(["synth", "cap", "--size", "16", "--lights", "3", "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert err == (
        "irtps: error: lights: 3 lights of 16x16 images (direct light, 4 bounces and their sums, float32 RGB) "
        "need 64.5 kB, more than the 10.0 kB available\n"
    )
    assert list(tmp_path.iterdir()) == []


_CHILD = """
import resource, sys
from irtps.cli.main import main
status = main(sys.argv[1:])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)  # kB on Linux
sys.exit(status)
"""


def _limit_address_space():
    """At most 1.5 GB for the child, so that a missing check fails instead of filling the machine."""
    resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))


@pytest.mark.skipif(sys.platform != "linux", reason="peak memory of a child process, Linux")
@pytest.mark.parametrize(
    "lights, size, message",
    [
        (
            "100000000",
            "96",
            "irtps: error: --lights: 100000000 is out of range: expected an integer from 3 to 100000\n",
        ),
        ("100000", "1024", "irtps: error: lights: 100000 lights of 1024x1024 images"),
    ],
)
def test_synth_with_absurdly_many_lights_is_refused_with_little_memory(lights, size, message, tmp_path):
    out = tmp_path / "s"
    argv = ["synth", "cap", "--out", str(out), "--lights", lights, "--size", size]
    result = subprocess.run(
        [sys.executable, "-c", _CHILD, *argv],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_address_space,
        check=False,
    )
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(message), result.stderr
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    peak_mb = int(result.stdout.split()[-1]) / 1024
    assert peak_mb < 400, peak_mb
    assert not out.exists()


# The helpers ---------------------------------------------------------------------------------


def test_available_memory_is_known_on_linux():
    available = available_memory_bytes()
    if sys.platform == "linux":
        total = (
            int(
                next(
                    line for line in Path("/proc/meminfo").read_text().splitlines() if line.startswith("MemTotal")
                ).split()[1]
            )
            * 1024
        )
        assert 0 < available <= total


def test_check_memory_names_the_field(monkeypatch):
    monkeypatch.setattr(irtps._shared.resources, "available_memory_bytes", lambda: 20_100_000_000)
    check_memory(20_100_000_000, "lights: fits exactly")
    with pytest.raises(IrtpsError) as error:
        check_memory(41_200_000_000, "lights: 100000000 lights of 96x96 images")
    assert str(error.value) == "lights: 100000000 lights of 96x96 images need 41.2 GB, more than the 20.1 GB available"
    monkeypatch.setattr(irtps._shared.resources, "available_memory_bytes", lambda: None)
    check_memory(10**30, "unknown memory: nothing is refused")


def test_format_bytes():
    assert [format_bytes(n) for n in (0, 999, 1000, 331_776, 999_960, 2.5e12, 7.74e13)] == [
        "0 B",
        "999 B",
        "1.0 kB",
        "331.8 kB",
        "1.0 MB",
        "2.5 TB",
        "77.4 TB",
    ]


@pytest.mark.skipif(
    not (sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"), reason="mallopt is glibc's"
)
def test_the_command_fixes_glibcs_mmap_threshold():
    # Its effect on a run's peak is measured by benches/memory_bench.py; here, that glibc
    # takes the setting.
    assert return_freed_memory()


# An allocation of the core that fails: an error, not an abort -------------------------------

_LIMITED_CHILD = """
import resource, sys
import irtps._shared.resources
from irtps import _core
from irtps.cli.main import main
margin = int(sys.argv[1])
irtps._shared.resources.available_memory_bytes = lambda: None  # as where it cannot be read: no check up front
in_use = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmSize")) * 1024
resource.setrlimit(resource.RLIMIT_AS, (in_use + margin, in_use + margin))
if sys.argv[2] == "read_images":
    try:
        _core.read_images([sys.argv[3]] * int(sys.argv[4]))
    except MemoryError as error:
        print(error, file=sys.stderr)
        sys.exit(3)
    sys.exit(0)
sys.exit(main(sys.argv[2:]))
"""


def _run_limited(margin, *argv):
    """Run `argv` (the command's, or ``read_images PATH COUNT``) in a child whose address space
    is limited to what it uses after the imports plus `margin` bytes."""
    return subprocess.run(
        [sys.executable, "-c", _LIMITED_CHILD, str(margin), *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


@pytest.mark.skipif(sys.platform != "linux", reason="address-space limit and /proc/self/status, Linux")
def test_an_image_too_large_for_the_address_space_is_a_memory_error_not_an_abort(tmp_path):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    _claim_exr_size(data / "images" / "000.exr", 10_000, 10_000)  # 1.2 GB of samples to decode
    result = _run_limited(256 << 20, "reconstruct", data, "--out", tmp_path / "out", "--quiet")
    assert result.returncode == 2, (result.returncode, result.stderr)
    image = data / "images" / "000.exr"
    assert result.stderr == (
        f"irtps: error: not enough memory ({image}: decoding its 10000x10000 data window: could not allocate 1200110592 bytes)\n"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(sys.platform != "linux", reason="address-space limit and /proc/self/status, Linux")
def test_a_stack_of_images_too_large_for_the_address_space_is_a_memory_error():
    image = MITSUBA / "images" / "000.exr"
    result = _run_limited(64 << 20, "read_images", image, 1000)  # 1000 x 96 x 96 x 12 bytes: 110.6 MB
    assert result.returncode == 3, (result.returncode, result.stderr)
    assert result.stderr == "the 1000 images of 96x96 as float32 RGB: could not allocate 110592000 bytes\n"


_CHOLESKY_CHILD = """
import resource, sys
import numpy as np
import scipy.sparse as sp
from irtps import _core
side, margin = int(sys.argv[1]), int(sys.argv[2])
line = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
matrix = sp.csr_matrix(sp.kron(sp.identity(side), line) + sp.kron(line, sp.identity(side)) + 1e-3 * sp.identity(side * side))
arrays = (matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64), matrix.data)
in_use = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmSize")) * 1024
resource.setrlimit(resource.RLIMIT_AS, (in_use + margin, in_use + margin))
try:
    _core.SparseCholesky(*arrays, "laplacian").solve(np.ones(side * side))
except MemoryError as error:
    print(error, file=sys.stderr)
    sys.exit(3)
"""


@pytest.mark.skipif(sys.platform != "linux", reason="address-space limit and /proc/self/status, Linux")
def test_a_factorisation_without_room_for_the_dense_kernels_workspace_is_a_memory_error():
    # faer's dense kernels take, on a thread's first matrix product, a workspace of twice
    # the L3 cache (at least 4 MiB) that cannot fail gracefully: the process aborted there
    # (or, factoring on rayon's threads, panicked when they could not be started).
    result = subprocess.run(
        [sys.executable, "-c", _CHOLESKY_CHILD, "24", str(3 << 20)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 3, (result.returncode, result.stderr)
    assert re.fullmatch(
        r"laplacian: the workspace of the dense matrix kernels: could not allocate \d+ bytes\n", result.stderr
    ), result.stderr


@pytest.mark.skipif(sys.platform != "linux", reason="address-space limit and /proc/self/status, Linux")
@pytest.mark.parametrize("margin_mib", [32, 64, 80])
def test_irtps_with_little_address_space_left_succeeds_or_says_so(margin_mib, tmp_path):
    # On a machine with 32 MiB of L3, 64 MiB left is refused at the integration's
    # factorisation (its dense kernels' workspace), which aborted the process before.
    out = tmp_path / "out"
    result = _run_limited(
        margin_mib << 20,
        "reconstruct",
        BALL,
        "--out",
        out,
        "--method",
        "irtps",
        "--iterations",
        "1",
        "--samples",
        "8",
        "--quiet",
    )
    errors = [line for line in result.stderr.splitlines() if not line.startswith("irtps: warning:")]
    if result.returncode == 0:
        assert errors == [] and (out / "normal.exr").is_file()
    else:
        assert result.returncode == 2, (result.returncode, result.stderr)
        assert len(errors) == 1 and errors[0].startswith("irtps: error: not enough memory ("), result.stderr
        assert not out.exists()
