"""Atomic output: folders and files appear complete or not at all."""

import errno
import os
import stat

import pytest
from irtps import DatasetError
from irtps.atomic import atomic_output_dir, atomic_write_bytes, atomic_write_text


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
