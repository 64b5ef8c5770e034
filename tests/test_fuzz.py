"""Each target of fuzz/fuzz_readers.py (atheris), run for a bounded number of inputs.

libFuzzer stops at the first input that raises anything but `DatasetError`, crashes the
process, takes more than 10 s or more than 2 GB, and exits non-zero. About 40 s in all.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris", reason="atheris has wheels for Linux x86_64, CPython 3.11 to 3.13 only")

FUZZER = Path(__file__).resolve().parents[1] / "fuzz" / "fuzz_readers.py"
RUNS = {"exr": 2000, "png": 2000, "scene": 3000, "dataset": 1000}


@pytest.mark.parametrize("target", list(RUNS))
def test_fuzz_target_finds_no_bug(tmp_path, target):
    corpus = tmp_path / "corpus"
    options = [f"-runs={RUNS[target]}", "-seed=1", "-timeout=10", "-rss_limit_mb=2048", "-keep_seed=1"]
    result = subprocess.run(
        [sys.executable, str(FUZZER), target, str(corpus), *options],
        cwd=tmp_path,
        env={**os.environ, "TMPDIR": str(tmp_path)},
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    assert f"Done {RUNS[target]} runs" in result.stderr
    assert len(list(corpus.iterdir())) >= 2  # seeded from the fixtures
