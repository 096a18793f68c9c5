"""Atomic files and folders (``persuasive._files``): unique temporaries, all-or-nothing
folders, one-line errors naming the user's path."""

import threading
from pathlib import Path

import pytest

from persuasive._files import (OutputError, atomic_folder, atomic_write, check_output_file,
                               check_output_folder)


def test_many_threads_write_the_same_file(tmp_path):
    target = tmp_path / "out.txt"
    errors = []
    start = threading.Barrier(8)

    def writer(i):
        start.wait()
        try:
            for _ in range(20):
                atomic_write(target, lambda p: p.write_text(f"writer {i}\n" * 1000))
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    text = target.read_text()
    assert len(set(text.splitlines())) == 1 and len(text.splitlines()) == 1000  # one whole write
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_temporary_names_are_unique_and_keep_the_extension(tmp_path):
    seen = []
    for _ in range(3):
        atomic_write(tmp_path / "a.parquet", lambda p: seen.append(p) or p.write_bytes(b"x"))
    assert len(set(seen)) == 3
    assert all(p.parent == tmp_path and p.name.endswith(".parquet") for p in seen)


def test_failed_write_keeps_the_old_file_and_names_the_users_path(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")

    def broken(p: Path):
        p.write_text("partial")
        raise RuntimeError("writer broke\nwith a second line")

    with pytest.raises(OutputError) as info:
        atomic_write(target, broken)
    assert str(info.value) == f"cannot write {str(target)!r}: writer broke"
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_missing_parent_is_not_created(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        check_output_file(tmp_path / "no" / "x.png", (".png",), "figure")
    with pytest.raises(OutputError, match="cannot write"):
        atomic_write(tmp_path / "no" / "x.png", lambda p: p.write_bytes(b""))
    assert not (tmp_path / "no").exists()


def test_check_output_file_rejects_folders_and_bad_extensions(tmp_path):
    (tmp_path / "d.png").mkdir()
    with pytest.raises(OutputError, match="it is a folder"):
        check_output_file(tmp_path / "d.png", (".png",))
    with pytest.raises(OutputError, match=r"unsupported extension '\.jpg'; allowed: \.png"):
        check_output_file(tmp_path / "x.jpg", (".png",))
    assert check_output_file(tmp_path / "X.PNG", (".png",)) == ".png"


def test_folder_is_written_as_a_set(tmp_path):
    target = tmp_path / "res"
    with atomic_folder(target) as tmp:
        (tmp / "a.txt").write_text("1")
        (tmp / "b.txt").write_text("2")
        assert not target.exists()  # nothing visible before the block ends
    assert sorted(p.name for p in target.iterdir()) == ["a.txt", "b.txt"]
    with pytest.raises(ZeroDivisionError):
        with atomic_folder(target) as tmp:
            (tmp / "a.txt").write_text("new")
            1 / 0
    assert (target / "a.txt").read_text() == "1"
    with atomic_folder(target) as tmp:
        (tmp / "c.txt").write_text("3")
    assert sorted(p.name for p in target.iterdir()) == ["c.txt"]  # replaced as a whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_folder_target_that_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputError, match="it is a file"):
        check_output_folder(tmp_path / "f")
    with pytest.raises(OutputError, match="is not a folder"):
        check_output_folder(tmp_path / "f" / "sub")
