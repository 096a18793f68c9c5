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
    with atomic_folder(target, owned=("*.txt",)) as tmp:
        (tmp / "a.txt").write_text("1")
        (tmp / "b.txt").write_text("2")
        assert not target.exists()  # nothing visible before the block ends
    assert sorted(p.name for p in target.iterdir()) == ["a.txt", "b.txt"]
    with pytest.raises(ZeroDivisionError):
        with atomic_folder(target, owned=("*.txt",)) as tmp:
            (tmp / "a.txt").write_text("new")
            1 / 0
    assert (target / "a.txt").read_text() == "1"
    with atomic_folder(target, owned=("*.txt",)) as tmp:
        (tmp / "c.txt").write_text("3")
    # only its own files: replaced as a whole
    assert sorted(p.name for p in target.iterdir()) == ["c.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_folder_target_that_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputError, match="it is a file"):
        check_output_folder(tmp_path / "f")
    with pytest.raises(OutputError, match="is not a folder"):
        check_output_folder(tmp_path / "f" / "sub")


# -- the true reason: a virtual file system, not "no such file or directory" ------------------

VIRTUAL = "that cannot hold result files"


def test_mount_type_takes_the_deepest_mount_and_reads_escapes(tmp_path, monkeypatch):
    from persuasive import _files

    mounts = tmp_path / "mounts"
    deep = tmp_path / "my dir" / "proc"
    (deep / "sub").mkdir(parents=True)
    escaped = str(deep).replace(" ", "\\040")
    mounts.write_text(f"/dev/sda1 / ext4 rw 0 0\nproc {escaped} proc rw 0 0\n"
                      f"tmpfs {escaped}/sub tmpfs rw 0 0\n")
    monkeypatch.setattr(_files, "MOUNTS", str(mounts))
    assert _files.mount_type(tmp_path) == "ext4"
    assert _files.mount_type(deep) == "proc"
    assert _files.mount_type(deep / "x" / "y") == "proc"
    assert _files.mount_type(deep / "sub" / "z") == "tmpfs"
    assert _files.mount_type(str(deep) + "x") == "ext4"  # a prefix is not a parent
    with pytest.raises(OutputError) as info:
        check_output_file(deep / "x.csv", (".csv",), "log")
    assert str(info.value) == (f"cannot write {str(deep / 'x.csv')!r}: {str(deep)!r} is on "
                               f"a virtual file system (proc) {VIRTUAL}")
    with pytest.raises(OutputError, match=f"virtual file system \\(proc\\) {VIRTUAL}$"):
        check_output_folder(deep / "a" / "b")
    check_output_folder(deep / "sub" / "z")  # tmpfs: fine
    monkeypatch.setattr(_files, "MOUNTS", str(tmp_path / "none"))  # not Linux: unknown
    assert _files.mount_type(deep) is None
    assert check_output_file(deep / "x.csv", (".csv",)) == ".csv"


@pytest.mark.skipif(not Path("/proc/self/mounts").exists(), reason="needs Linux's /proc")
def test_proc_and_sys_are_named_as_virtual(tmp_path):
    with pytest.raises(OutputError) as info:
        check_output_file("/proc/x.csv", (".csv",), "log")
    assert str(info.value) == ("cannot write '/proc/x.csv': '/proc' is on a virtual file "
                               f"system (proc) {VIRTUAL}")
    with pytest.raises(OutputError) as info:
        check_output_folder("/proc", "comparison folder")
    assert str(info.value) == ("comparison folder '/proc' cannot be written: '/proc' is on a "
                               f"virtual file system (proc) {VIRTUAL}")
    with pytest.raises(OutputError) as info:  # the write itself fails for the same reason
        atomic_write("/proc/x.csv", lambda p: p.write_text("x"))
    assert str(info.value) == ("cannot write '/proc/x.csv': '/proc' is on a virtual file "
                               f"system (proc) {VIRTUAL}")
    with pytest.raises(OutputError) as info:
        with atomic_folder("/sys/kernel/res"):
            pass
    assert str(info.value).endswith(f"'/sys/kernel' is on a virtual file system (sysfs) "
                                    f"{VIRTUAL}")


def test_a_folder_without_write_permission_is_named(tmp_path, monkeypatch):
    import os

    real = os.access
    locked = tmp_path / "locked"
    locked.mkdir()
    # root passes every permission check, so the refusal is simulated
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == locked
                        else real(p, mode))
    with pytest.raises(OutputError) as info:
        check_output_file(locked / "x.png", (".png",), "figure")
    assert str(info.value) == (f"cannot write {str(locked / 'x.png')!r}: {str(locked)!r} is "
                               "not writable")
    with pytest.raises(OutputError, match="is not writable"):
        check_output_folder(locked)  # an existing folder receives the files itself
