"""Atomic output: folders and files appear complete or not at all."""

import errno
import fcntl
import os
import shutil
import signal
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from irtps import DatasetError
from irtps._shared.atomic import atomic_output_dir, atomic_write_bytes, atomic_write_text


class Boom(Exception):
    pass


def test_output_dir_is_built_next_to_the_target_then_renamed(tmp_path):
    final = tmp_path / "out"
    with atomic_output_dir(final) as temp:
        assert temp.parent == tmp_path
        assert temp.name.startswith(".out.tmp-")
        assert temp.is_dir() and not any(temp.iterdir())
        assert not final.exists()
        (temp / "a.txt").write_text("a")
    assert (final / "a.txt").read_text() == "a"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_output_dir_replaces_an_existing_folder_and_leaves_nothing_behind(tmp_path):
    final = tmp_path / "out"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with atomic_output_dir(final) as temp:
        (temp / "new.txt").write_text("new")
        assert (final / "old.txt").exists()
    assert sorted(p.name for p in final.iterdir()) == ["new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_output_dir_replaces_an_existing_file(tmp_path):
    final = tmp_path / "out"
    final.write_text("a file")
    with atomic_output_dir(final) as temp:
        (temp / "new.txt").write_text("new")
    assert final.is_dir() and (final / "new.txt").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_output_dir_failure_keeps_the_old_folder_and_removes_the_temporary_one(tmp_path):
    final = tmp_path / "out"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with pytest.raises(Boom), atomic_output_dir(final) as temp:
        (temp / "half.txt").write_text("half")
        raise Boom()
    assert not temp.exists()
    assert sorted(p.name for p in final.iterdir()) == ["old.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_output_dir_failure_creates_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt), atomic_output_dir(tmp_path / "out") as temp:
        (temp / "sub").mkdir()
        raise KeyboardInterrupt()
    assert list(tmp_path.iterdir()) == []


def test_output_dir_creates_missing_parents(tmp_path):
    final = tmp_path / "a" / "b" / "out"
    with atomic_output_dir(final) as temp:
        (temp / "x").write_text("x")
    assert (final / "x").read_text() == "x"


def test_output_dir_respects_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        with atomic_output_dir(tmp_path / "out"):
            pass
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) == 0o755


def test_output_dir_under_a_file_names_the_folder(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    with pytest.raises(DatasetError) as info, atomic_output_dir(blocker / "out"):
        pytest.fail("the body must not run")
    assert str(blocker) in str(info.value)
    assert "cannot create the output folder" in str(info.value)


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write to read-only folders")
def test_output_dir_in_a_read_only_folder_names_the_folder(tmp_path):
    parent = tmp_path / "locked"
    parent.mkdir()
    parent.chmod(0o555)
    try:
        with (
            pytest.raises(DatasetError, match="the output folder is not writable") as info,
            atomic_output_dir(parent / "out"),
        ):
            pytest.fail("the body must not run")
        assert str(info.value).startswith(f"{parent}: ")
    finally:
        parent.chmod(0o755)


def test_output_dir_denied_by_the_file_system_names_the_folder(tmp_path, monkeypatch):
    def refuse(path, *args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(os, "mkdir", refuse)
    with pytest.raises(DatasetError) as info, atomic_output_dir(tmp_path / "out"):
        pytest.fail("the body must not run")
    assert str(info.value) == f"{tmp_path}: the output folder is not writable (Permission denied)"
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


def test_write_text_creates_and_replaces_without_leftovers(tmp_path):
    path = tmp_path / "sub" / "note.txt"
    atomic_write_text(path, "first\n")
    assert path.read_text() == "first\n"
    atomic_write_text(path, "second é\n")
    assert path.read_text(encoding="utf-8") == "second é\n"
    assert [p.name for p in path.parent.iterdir()] == ["note.txt"]


def test_write_bytes_respects_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "data.bin", b"\x00\x01")
    finally:
        os.umask(old)
    assert (tmp_path / "data.bin").read_bytes() == b"\x00\x01"
    assert stat.S_IMODE((tmp_path / "data.bin").stat().st_mode) == 0o644


def test_write_bytes_failure_keeps_the_old_file(tmp_path):
    path = tmp_path / "data.bin"
    path.write_bytes(b"old")
    with pytest.raises(TypeError):
        atomic_write_bytes(path, "not bytes")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["data.bin"]


def test_write_bytes_under_a_file_names_the_folder(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    with pytest.raises(DatasetError, match="blocker: cannot create the output folder"):
        atomic_write_bytes(blocker / "data.bin", b"x")


# Stale hidden names of killed writes, and concurrent writes.

# Enters atomic_output_dir(argv[1]) (or atomic_write_bytes when argv[2] is "file"),
# writes, prints the temporary name, then waits for a line on stdin (or to be killed)
# before finishing. With argv[3] == "mid-replace", it stops instead right after the
# old output was moved aside, before the new one is renamed in; with "deleting-old",
# when it starts deleting the old output, after the new one is in place.
WRITER = """
import os, shutil, sys
from irtps._shared.atomic import atomic_output_dir, atomic_write_bytes

final, kind, when = sys.argv[1], sys.argv[2], sys.argv[3]

def pause(temp):
    print(temp, flush=True)
    sys.stdin.readline()

if kind == "file":
    replace = os.replace
    def paused_replace(source, target):
        pause(source)
        replace(source, target)
    os.replace = paused_replace
    atomic_write_bytes(final, b"from the writer")
else:
    if when == "mid-replace":
        rename = os.rename
        def paused_rename(source, target):
            rename(source, target)
            if ".old-" in str(target):
                pause(target)
        os.rename = paused_rename
    if when == "deleting-old":
        rmtree = shutil.rmtree
        def paused_rmtree(path, **kwargs):
            pause(path)
            rmtree(path, **kwargs)
        shutil.rmtree = paused_rmtree
    with atomic_output_dir(final) as temp:
        (temp / "a.txt").write_text("from the writer")
        if when == "in-body":
            pause(temp)
print("done", flush=True)
"""


def _start_writer(final, kind="dir", when="in-body"):
    process = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(final), kind, when],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline()
    assert line, "the writer died before writing"
    return process, Path(line.strip())


def _kill(process):
    process.kill()
    process.wait()
    process.stdin.close()
    process.stdout.close()
    assert process.returncode == -signal.SIGKILL


def _names(folder):
    return sorted(p.name for p in folder.iterdir())


def test_a_killed_writer_leaves_hidden_names_that_the_next_write_removes(tmp_path):
    final = tmp_path / "out"
    process, temp = _start_writer(final)
    assert temp.parent == tmp_path and temp.name.startswith(".out.tmp-")
    token = temp.name.rpartition("-")[2]
    _kill(process)
    assert _names(tmp_path) == [f".out.lock-{token}", f".out.tmp-{token}"]
    with atomic_output_dir(final) as new:
        (new / "b.txt").write_text("b")
    assert _names(tmp_path) == ["out"]
    assert _names(final) == ["b.txt"]


def test_a_failed_write_also_removes_the_hidden_names_of_a_killed_one(tmp_path):
    final = tmp_path / "out"
    _kill(_start_writer(final)[0])
    with pytest.raises(Boom), atomic_output_dir(final):
        raise Boom()
    assert list(tmp_path.iterdir()) == []


def test_a_writer_killed_mid_replace_loses_nothing(tmp_path):
    final = tmp_path / "out"
    final.mkdir()
    (final / "previous.txt").write_text("previous")
    process, old = _start_writer(final, when="mid-replace")
    assert old.name.startswith(".out.old-")
    _kill(process)
    assert not final.exists()
    assert (old / "previous.txt").read_text() == "previous"
    with pytest.raises(Boom), atomic_output_dir(final):
        raise Boom()
    assert _names(tmp_path) == ["out"]
    assert _names(final) == ["previous.txt"]


def _stale_mid_replace(folder, lock):
    """Make what a write killed between its two renames leaves: the previous output moved
    aside, the new one complete but not renamed in, the lock file free (or gone)."""
    (folder / ".out.old-0123abcd").mkdir()
    (folder / ".out.old-0123abcd" / "previous.txt").write_text("previous")
    (folder / ".out.tmp-0123abcd").mkdir()
    (folder / ".out.tmp-0123abcd" / "new.txt").write_text("new")
    if lock == "unlocked":
        (folder / ".out.lock-0123abcd").write_bytes(b"")


def test_a_writer_killed_while_deleting_the_old_output_leaves_no_old_folder(tmp_path):
    final = tmp_path / "out"
    final.mkdir()
    (final / "previous.txt").write_text("previous")
    process, deleting = _start_writer(final, when="deleting-old")
    _kill(process)
    assert deleting.name.startswith(".out.tmp-")  # the old output, renamed to the free temporary name
    assert _names(deleting) == ["previous.txt"]
    assert _names(final) == ["a.txt"]
    shutil.rmtree(final)  # by hand: the next write must not bring back what was being deleted
    with pytest.raises(Boom), atomic_output_dir(final):
        raise Boom()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("lock", ["unlocked", "gone"])
def test_a_stale_old_folder_is_restored_when_the_output_is_missing(tmp_path, lock):
    _stale_mid_replace(tmp_path, lock)
    with atomic_output_dir(tmp_path / "out") as temp:
        token = temp.name.rpartition("-")[2]
        assert _names(tmp_path) == sorted(["out", temp.name, f".out.lock-{token}"])
        assert _names(tmp_path / "out") == ["previous.txt"]
        (temp / "third.txt").write_text("third")
    assert _names(tmp_path) == ["out"]
    assert _names(tmp_path / "out") == ["third.txt"]


@pytest.mark.parametrize("lock", ["unlocked", "gone"])
def test_a_stale_old_folder_is_deleted_when_the_output_exists(tmp_path, lock):
    _stale_mid_replace(tmp_path, lock)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "newer.txt").write_text("newer")
    with pytest.raises(Boom), atomic_output_dir(tmp_path / "out"):
        raise Boom()
    assert _names(tmp_path) == ["out"]
    assert _names(tmp_path / "out") == ["newer.txt"]


def test_only_the_hidden_names_of_the_same_output_are_cleaned(tmp_path):
    others = [".out.tmp-0123abc", ".out.tmp-0123abcd.x", ".out2.tmp-0123abcd", ".xout.old-0123abcd", "out.tmp-0123abcd"]
    for name in others:
        (tmp_path / name).mkdir()
    (tmp_path / "sub").mkdir()
    _stale_mid_replace(tmp_path / "sub", "unlocked")
    with atomic_output_dir(tmp_path / "out"):
        pass
    assert _names(tmp_path) == sorted([*others, "out", "sub"])
    assert _names(tmp_path / "sub") == [".out.lock-0123abcd", ".out.old-0123abcd", ".out.tmp-0123abcd"]


def test_a_killed_file_writer_leaves_a_temporary_file_that_the_next_write_removes(tmp_path):
    path = tmp_path / "data.bin"
    process, temp = _start_writer(path, kind="file")
    assert temp.read_bytes() == b"from the writer"
    token = temp.name.rpartition("-")[2]
    _kill(process)
    assert _names(tmp_path) == [f".data.bin.lock-{token}", f".data.bin.tmp-{token}"]
    atomic_write_bytes(path, b"new")
    assert _names(tmp_path) == ["data.bin"]
    assert path.read_bytes() == b"new"


def _finish(process):
    out, _ = process.communicate("\n", timeout=60)
    assert process.returncode == 0 and out == "done\n"


@pytest.mark.parametrize("kind", ["dir", "file"])
def test_the_hidden_names_of_a_live_writer_are_left_alone(tmp_path, kind):
    final = tmp_path / "out"
    process, temp = _start_writer(final, kind=kind)
    try:
        hidden = _names(tmp_path)
        for _ in range(3):
            if kind == "file":
                atomic_write_bytes(final, b"mine")
            else:
                with atomic_output_dir(final) as mine:
                    (mine / "b.txt").write_text("b")
            with pytest.raises(Boom), atomic_output_dir(final):
                raise Boom()
            assert _names(tmp_path) == sorted([*hidden, "out"])
        assert (temp.read_bytes() if kind == "file" else (temp / "a.txt").read_bytes()) == b"from the writer"
        _finish(process)
    finally:
        process.kill()
        process.wait()
    assert _names(tmp_path) == ["out"]
    assert (final.read_bytes() if kind == "file" else (final / "a.txt").read_bytes()) == b"from the writer"


def test_nested_writes_in_one_process_do_not_clean_each_other(tmp_path):
    final = tmp_path / "out"
    with atomic_output_dir(final) as outer:
        (outer / "outer.txt").write_text("outer")
        with atomic_output_dir(final) as inner:
            (inner / "inner.txt").write_text("inner")
        assert _names(outer) == ["outer.txt"]
    assert _names(final) == ["outer.txt"]
    assert _names(tmp_path) == ["out"]


# Each racer prints "ready" once imported, waits for a line on stdin, then writes the
# same output ROUNDS times, each time all of its parts with the stamp WRITER-ROUND.
RACER = """
import sys
from irtps._shared.atomic import atomic_output_dir, atomic_write_bytes

final, kind, writer, rounds = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
print("ready", flush=True)
sys.stdin.readline()
for round in range(rounds):
    stamp = f"{writer}-{round}"
    if kind == "file":
        atomic_write_bytes(final, stamp.encode() * 1000)
    else:
        with atomic_output_dir(final) as temp:
            for part in range(5):
                (temp / f"{part}.txt").write_text(stamp * 1000)
"""


@pytest.mark.parametrize("kind", ["dir", "file"])
def test_concurrent_writers_never_fail_nor_leave_hidden_names(tmp_path, kind):
    final, writers, rounds = tmp_path / "out", 8, 40
    if kind == "dir":
        final.mkdir()
        (final / "previous.txt").write_text("previous")
    processes = [
        subprocess.Popen(
            [sys.executable, "-c", RACER, str(final), kind, str(writer), str(rounds)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for writer in range(writers)
    ]
    try:
        assert [process.stdout.readline() for process in processes] == ["ready\n"] * writers
        for process in processes:
            process.stdin.write("\n")
            process.stdin.flush()
        results = [process.communicate(timeout=120) for process in processes]
    finally:
        for process in processes:
            process.kill()
            process.wait()
    assert [(process.returncode, err) for process, (_, err) in zip(processes, results)] == [(0, "")] * writers
    assert _names(tmp_path) == ["out"]
    if kind == "file":
        content = final.read_text()
        stamp = content[: len(content) // 1000]
        assert content == stamp * 1000
    else:
        assert _names(final) == [f"{part}.txt" for part in range(5)]
        contents = {(final / f"{part}.txt").read_text() for part in range(5)}
        assert len(contents) == 1
        content = contents.pop()
        stamp = content[: len(content) // 1000]
        assert content == stamp * 1000
    # The last rename into place is some writer's last round.
    writer, _, round = stamp.partition("-")
    assert int(writer) in range(writers) and round == str(rounds - 1)


def test_a_denied_rename_into_place_keeps_the_old_folder_and_names_the_folder(tmp_path, monkeypatch):
    final = tmp_path / "out"
    final.mkdir()
    (final / "old.txt").write_text("old")
    rename = os.rename

    def refuse_temporary(source, target):
        if Path(source).name.startswith(".out.tmp-"):
            raise PermissionError(errno.EACCES, "Permission denied", str(source))
        rename(source, target)

    monkeypatch.setattr(os, "rename", refuse_temporary)
    with pytest.raises(DatasetError) as info, atomic_output_dir(final) as temp:
        (temp / "new.txt").write_text("new")
    assert str(info.value) == f"{tmp_path}: the output folder is not writable (Permission denied)"
    assert _names(tmp_path) == ["out"]
    assert _names(final) == ["old.txt"]


def test_a_file_system_without_locks_names_the_folder(tmp_path, monkeypatch):
    def refuse(*args):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", refuse)
    with pytest.raises(DatasetError) as info, atomic_output_dir(tmp_path / "out"):
        pytest.fail("the body must not run")
    assert str(info.value) == f"{tmp_path}: cannot lock a file in the output folder (No locks available)"
    assert list(tmp_path.iterdir()) == []
