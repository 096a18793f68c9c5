"""The compiled kernels' on-disk cache: is it warm, and is it up to date?

The kernels are compiled with ``cache=True``: the first process compiles them (about 25 s on
the 2-core machine CI uses) and writes them next to the sources (or into
``NUMBA_CACHE_DIR``); every later process loads them.

Numba checks a cached function against its own source file only. A cached function carries
the code of every function it calls, so after an edit in a *called* function in another file
it would load stale code (wrong results, not an error). :func:`ensure_fresh_cache` closes
that gap: it keeps a stamp of the package's sources and clears the package's cached kernels
when any source changed, before anything is loaded. A user who extends the method by editing
a kernel therefore always runs what they wrote. :func:`warm_up` loads them (compiling them
once when they are not cached) in this process, e.g. before worker processes start.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
_STAMP = "persuasive-kernels.stamp"
_SUFFIXES = (".nbi", ".nbc")


#: Modules without compiled functions whose constants the kernels compile in.
_CONSTANT_MODULES = ("packing.py", "policies/kinds.py")


def kernel_sources() -> list[Path]:
    """The sources the compiled kernels are made of: every module that compiles functions,
    and the modules of constants they read."""
    out = []
    for path in sorted(_PACKAGE.rglob("*.py")):
        rel = path.relative_to(_PACKAGE).as_posix()
        if rel in _CONSTANT_MODULES or b"@njit" in path.read_bytes():
            out.append(path)
    return out


def sources_digest() -> str:
    """A hash of the kernel sources of the package (path and content): an edit of a command,
    a figure or the web page does not touch the compiled code."""
    h = hashlib.sha256()
    for path in kernel_sources():
        h.update(str(path.relative_to(_PACKAGE)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def _cache_dirs() -> list[Path]:
    dirs = [p for p in _PACKAGE.rglob("__pycache__") if p.is_dir()]
    custom = os.environ.get("NUMBA_CACHE_DIR")
    if custom and Path(custom).is_dir():
        dirs += [p for p in Path(custom).rglob("*") if p.is_dir() and "persuasive" in str(p)]
    return dirs


def _stamp_path() -> Path:
    custom = os.environ.get("NUMBA_CACHE_DIR")
    return Path(custom) / _STAMP if custom else _PACKAGE / "__pycache__" / _STAMP


@contextlib.contextmanager
def _stamp_lock(stamp: Path):
    """An exclusive lock on a file beside the stamp while it is checked, the cache cleared
    and the stamp written (POSIX ``flock``; none where the folder cannot be written or there
    is no ``fcntl``): of processes importing the package at once in a fresh checkout (a test
    run's workers), one clears the stale kernels and writes the stamp, the others wait and then
    find the stamp fresh. Without it a second process that had read "no stamp" could clear
    kernels the first one had already compiled again (a recompile, not a wrong result)."""
    try:
        import fcntl

        stamp.parent.mkdir(parents=True, exist_ok=True)
        fh = open(stamp.with_name(f".{stamp.name}.lock"), "a")
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fh, fcntl.LOCK_EX)
        yield
    finally:
        fh.close()  # releases the lock


def ensure_fresh_cache() -> bool:
    """Clear the package's cached kernels if any source changed since they were cached.

    Returns True when it cleared them. One process at a time (:func:`_stamp_lock`). Errors (a
    read-only install) leave the cache as it is: Numba's own checks still apply.
    """
    digest = sources_digest()
    stamp = _stamp_path()
    with _stamp_lock(stamp):
        return _clear_if_stale(stamp, digest)


def _clear_if_stale(stamp: Path, digest: str) -> bool:
    try:
        if stamp.read_text(encoding="ascii").strip() == digest:
            return False
    except OSError:
        pass
    try:
        for folder in _cache_dirs():
            for entry in folder.iterdir():
                if entry.suffix in _SUFFIXES:
                    entry.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f".{stamp.name}.{os.getpid()}")
        tmp.write_text(digest + "\n", encoding="ascii")
        os.replace(tmp, stamp)
    except OSError:
        return False
    return True


def kernels_cached(*kernels) -> bool:
    """True when these compiled functions (default: the closed loop's, ``world.run_loop``)
    are cached and newer than their sources."""
    if not kernels:
        from .world import run_loop

        kernels = (run_loop,)
    for kernel in kernels:
        try:
            index = kernel._cache._cache_file._index_path  # numba's cache layout
            source = kernel.py_func.__code__.co_filename
            if os.path.getmtime(index) < os.path.getmtime(source):
                return False
        except (AttributeError, OSError):
            return False
    return True


def warm_up() -> None:
    """Load (or compile, on first use) the kernels in this process before workers start."""
    from .config import Config
    from .simulation import simulate

    simulate(Config().with_overrides({"simulation.n_steps": 1}), 1)
    simulate(Config().with_overrides({"simulation.n_steps": 1, "av.kind": "lfg"}), 1)
