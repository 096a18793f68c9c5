"""The compiled kernels' on-disk cache: is it warm, and is it up to date?

The kernels are compiled with ``cache=True``: the first process that calls one compiles it and
writes it next to the sources (or into ``NUMBA_CACHE_DIR``); every later process loads it.
``persuasive compile`` (``make setup`` runs it) compiles every kernel any command calls at
once, about 3 minutes of one core; afterwards a command only loads them (1 to 2 s).
:func:`compile_seconds` counts the time this process spent compiling, so that a command
reports it apart from its own time (:class:`StudyClock`).

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
import re
import time
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
_STAMP = "persuasive-kernels.stamp"
_SUFFIXES = (".nbi", ".nbc")


#: Modules without compiled functions whose constants the kernels compile in.
_CONSTANT_MODULES = ("packing.py", "policies/kinds.py")


#: A compiled function's decorator, at the start of a line (this module names it, and is none).
_DECORATOR = re.compile(rb"^[ \t]*@(numba\.)?njit\b", re.MULTILINE)


def kernel_sources() -> list[Path]:
    """The sources the compiled kernels are made of: every module that compiles functions,
    and the modules of constants they read."""
    out = []
    for path in sorted(_PACKAGE.rglob("*.py")):
        rel = path.relative_to(_PACKAGE).as_posix()
        if rel in _CONSTANT_MODULES or _DECORATOR.search(path.read_bytes()):
            out.append(path)
    return out


def sources_digest() -> str:
    """A hash of the kernel sources of the package (path and content): an edit of a command,
    a figure or the web page does not touch the compiled code."""
    h = hashlib.sha256()
    for path in kernel_sources():
        h.update(str(path.relative_to(_PACKAGE)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def _numba_cache_folder(root: Path, folder: Path) -> Path:
    """Where Numba caches the kernels of the sources in ``folder`` under a user cache folder
    ``root`` (``NUMBA_CACHE_DIR``): one flat folder per source folder, named after it and a
    hash of its absolute path (numba.core.caching's ``get_suitable_cache_subpath``)."""
    path = os.path.abspath(folder)
    return root / f"{os.path.basename(path)}_{hashlib.sha1(path.encode()).hexdigest()}"


def _cache_dirs() -> list[Path]:
    """The folders holding this package's cached kernels: its ``__pycache__`` folders, or with
    ``NUMBA_CACHE_DIR`` set only that folder's subfolders for the package's source folders
    (Numba then never reads the ``__pycache__`` ones, so a process using another cache never
    touches the user's)."""
    folders = sorted({p.parent for p in _PACKAGE.rglob("*.py")} | {_PACKAGE})
    custom = os.environ.get("NUMBA_CACHE_DIR")
    if custom:
        dirs = [_numba_cache_folder(Path(custom), f) for f in folders]
    else:
        dirs = [f / "__pycache__" for f in folders]
    return [d for d in dirs if d.is_dir()]


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


def listen(kind: str, on_start, on_end) -> None:
    """Call ``on_start()`` and ``on_end()`` at every start and end of Numba's event ``kind``
    (``numba.core.event``: ``"numba:compile"``, ``"numba:compiler_lock"``), in the thread
    where it happens."""
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, _event) -> None:
            on_start()

        def on_end(self, _event) -> None:
            on_end()

    event.register(kind, Listener())


class _Compiles:
    """Time this process spent in Numba's compiler (its ``numba:compile`` events, the
    outermost only: a kernel's callees compile inside it). Loading a cached kernel is not a
    compile and is not counted."""

    seconds = 0.0
    depth = 0
    start = 0.0
    installed = False

    @classmethod
    def _started(cls) -> None:
        if cls.depth == 0:
            cls.start = time.perf_counter()
        cls.depth += 1

    @classmethod
    def _ended(cls) -> None:
        cls.depth = max(0, cls.depth - 1)
        if cls.depth == 0:
            cls.seconds += time.perf_counter() - cls.start

    @classmethod
    def install(cls) -> None:
        if not cls.installed:
            listen("numba:compile", cls._started, cls._ended)
            cls.installed = True


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels since the first call (which starts
    the count: call it before the work whose compiles should be counted)."""
    _Compiles.install()
    running = time.perf_counter() - _Compiles.start if _Compiles.depth else 0.0
    return _Compiles.seconds + running


class StudyClock:
    """A study's wall time without the kernel compiles that happened in it: ``seconds`` is the
    time since the clock started less ``compile_s``, the compiles of this process since then
    (a first run's compile is said apart: "compiled the numerical kernels in 158.2 s", then
    "16000 runs in 58.3 s")."""

    def __init__(self) -> None:
        self._c0 = compile_seconds()
        self._t0 = time.perf_counter()

    @property
    def compile_s(self) -> float:
        """Seconds spent compiling kernels since the clock started."""
        return compile_seconds() - self._c0

    @property
    def seconds(self) -> float:
        """Seconds since the clock started, compiles excluded."""
        return max(0.0, time.perf_counter() - self._t0 - self.compile_s)
