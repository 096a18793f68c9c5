"""The compiled kernels' cache guard (``persuasive._compile``): an edit in any source of the
package clears the cached kernels, so a function never runs a stale copy of a callee."""

from __future__ import annotations

from pathlib import Path

import persuasive._compile as comp


def _fake_package(root):
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "__pycache__").mkdir()
    (root / "a.py").write_text("@njit\ndef f(): pass\n")
    (root / "sub" / "b.py").write_text("@njit\ndef g(): pass\n")
    (root / "sub" / "plain.py").write_text("z = 0\n")
    caches = [root / "__pycache__" / "a.f-1.py311.nbi", root / "__pycache__" / "a.f-1.py311.1.nbc",
              root / "sub" / "__pycache__" / "b.g-3.py311.nbi"]
    for c in caches:
        c.write_bytes(b"cached")
    keep = root / "__pycache__" / "a.cpython-311.pyc"
    keep.write_bytes(b"bytecode")
    return caches, keep


def test_an_edit_anywhere_clears_the_cached_kernels(tmp_path, monkeypatch):
    monkeypatch.setattr(comp, "_PACKAGE", tmp_path)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    caches, keep = _fake_package(tmp_path)
    assert comp.ensure_fresh_cache() is True  # no stamp yet: cleared, stamp written
    assert not any(c.exists() for c in caches) and keep.exists()
    for c in caches:  # the kernels compiled again
        c.write_bytes(b"cached")
    assert comp.ensure_fresh_cache() is False  # nothing changed: the cache stands
    assert all(c.exists() for c in caches)
    (tmp_path / "sub" / "plain.py").write_text("z = 1\n")  # no kernel in it: no effect
    assert comp.ensure_fresh_cache() is False
    (tmp_path / "sub" / "b.py").write_text("@njit\ndef g(): return 1\n")  # a kernel's file
    assert comp.ensure_fresh_cache() is True
    assert not any(c.exists() for c in caches) and keep.exists()


def test_a_second_process_waits_for_the_first_and_keeps_what_it_compiled(tmp_path, monkeypatch):
    """While one process holds the stamp's lock (it is clearing the stale kernels), another
    waits; it then finds the stamp fresh and leaves the kernels the first compiled in the
    meantime (without the lock it would clear them: it had found no stamp)."""
    import fcntl
    import threading

    monkeypatch.setattr(comp, "_PACKAGE", tmp_path)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    caches, _ = _fake_package(tmp_path)
    stamp = comp._stamp_path()
    result = []
    with open(stamp.with_name(f".{stamp.name}.lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the first process, clearing
        other = threading.Thread(target=lambda: result.append(comp.ensure_fresh_cache()))
        other.start()
        other.join(0.5)
        assert other.is_alive()  # the second waits for the lock
        stamp.write_text(comp.sources_digest() + "\n", encoding="ascii")  # the first's stamp
    other.join(10)
    assert result == [False] and all(c.exists() for c in caches)


def test_the_stamp_follows_numba_cache_dir(tmp_path, monkeypatch):
    pkg, cache = tmp_path / "pkg", tmp_path / "cache"
    pkg.mkdir()
    (pkg / "a.py").write_text("@njit\ndef f(): pass\n")
    stale = comp._numba_cache_folder(cache, pkg) / "a.f-1.py311.nbi"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"cached")
    monkeypatch.setattr(comp, "_PACKAGE", pkg)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    assert comp.ensure_fresh_cache() is True
    assert not stale.exists() and (cache / comp._STAMP).exists()


def test_another_cache_dir_leaves_the_package_s_own_cache_alone(tmp_path, monkeypatch):
    """A process with ``NUMBA_CACHE_DIR`` set (a test's empty folder) checks and clears only
    that folder's kernels: the package's ``__pycache__`` ones (the user's cache, which Numba
    does not read then) survive, and so do other packages' kernels in the same folder."""
    pkg, cache = tmp_path / "pkg", tmp_path / "cache"
    pkg.mkdir()
    caches, keep = _fake_package(pkg)
    stale = [comp._numba_cache_folder(cache, pkg / "sub") / "b.g-3.py311.nbi"]
    other = cache / "elsewhere_0123" / "c.h-1.py311.nbi"
    for c in stale + [other]:
        c.parent.mkdir(parents=True, exist_ok=True)
        c.write_bytes(b"cached")
    monkeypatch.setattr(comp, "_PACKAGE", pkg)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    assert comp.ensure_fresh_cache() is True  # no stamp in the empty cache folder
    assert not any(c.exists() for c in stale)
    assert all(c.exists() for c in caches) and keep.exists() and other.exists()
    assert not (pkg / "__pycache__" / comp._STAMP).exists()


def test_the_cache_folders_are_numba_s(tmp_path, monkeypatch):
    """The folder :func:`persuasive._compile._cache_dirs` clears under ``NUMBA_CACHE_DIR`` is
    the one Numba writes a kernel of the package to."""
    from numba.core.caching import _CacheLocator

    from persuasive.safety.shield import shield_filter

    src = shield_filter.py_func.__code__.co_filename
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert comp._numba_cache_folder(tmp_path, Path(src).parent) == \
        tmp_path / _CacheLocator.get_suitable_cache_subpath(src)


def test_first_use_announces_the_compilation_in_one_line(capsys, monkeypatch):
    from persuasive.cli import main

    monkeypatch.setattr(comp, "kernels_cached", lambda: False)
    assert main(["simulate", "--seed", "3", "--json"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("compiling the numerical kernels once") and err.count("\n") == 1
    monkeypatch.setattr(comp, "kernels_cached", lambda: True)
    assert main(["simulate", "--seed", "3", "--json"]) == 0
    assert capsys.readouterr().err == ""


def test_kernels_cached_follows_the_cache_index(monkeypatch, tmp_path):
    """Against an index file of the test's own: the package's real cache is shared with the
    other worker, which (in a fresh clone, under load) may clear it between two lines here."""
    import os

    from persuasive.world import run_loop

    cache_file = run_loop._cache._cache_file
    source = os.path.getmtime(run_loop.py_func.__code__.co_filename)
    index = tmp_path / "run_loop.nbi"
    index.write_bytes(b"")
    monkeypatch.setattr(cache_file, "_index_path", str(index))
    os.utime(index, (source + 10.0, source + 10.0))
    assert comp.kernels_cached()  # an index newer than the source
    os.utime(index, (source - 10.0, source - 10.0))
    assert not comp.kernels_cached()  # older: the source changed since
    monkeypatch.setattr(cache_file, "_index_path", str(tmp_path / "none.nbi"))
    assert not comp.kernels_cached()  # none
