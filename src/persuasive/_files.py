"""Writing result files and folders atomically, one writer at a time, with one-line errors
that name the user's path.

- :func:`check_output_file` checks a file target before any work: a known extension, an
  existing parent folder that is a folder (missing folders are *not* created for a file
  target), and no folder in the way.
- :func:`atomic_write` writes a file through a unique temporary sibling (``mkstemp`` in the
  target folder, so two threads or processes never share one), fsyncs it, then renames it
  into place; a failure leaves the target as it was and removes the temporary file.
- :func:`atomic_folder` writes a whole results folder: every file into a temporary sibling
  folder, then into place (below).
- :func:`writer_lock` makes a command the only writer of its target (below).

**What a command owns, and what ``--force`` means.** No command deletes a file it did not
write, with or without ``--force``. Every command that writes a folder knows its own files by
name: a fixed set of names or patterns per command (``owned``, glob patterns of the folder's
top-level file names: ``summary.json``, ``vehicle_tracks_*.csv``, ...; a sweep's
``manifest.json``, ``runs/part-*.parquet`` and ``failed/failed-*.json``, see
:mod:`persuasive.sweep.store`). Names, not a manifest, so that folders written before this
rule are recognised too; a user's file that bears one of those names is taken for the
command's (the ``--force`` help of each command lists them). ``--force`` means the same in
every command: *replace this command's own earlier results in that folder*; every other entry
(a user's ``notes.txt``, a subfolder) is kept. Without ``--force`` a folder written as a whole
that holds anything is refused, before any work, in one line naming the folder and one of its
files (:func:`check_replaceable_folder`). With ``--force``, :func:`atomic_folder` swaps the
folder as a whole when it holds only the command's own files (readers see the old set or the
new one, never a mix); when it holds anything else it moves each new file into place with
``os.replace`` (each atomic), then removes the command's own files that the new result no
longer has, and leaves everything else where it is.

**One writer per target.** :func:`writer_lock` takes an advisory lock (``flock``,
``LOCK_EX | LOCK_NB``) on a lock file *beside* the target, ``.<name>.persuasive.lock`` in the
target's parent folder, for a folder and a file alike, and holds it for the whole command
(the CLI enters it once its checks pass, before any work, and leaves it when the command
ends: ``persuasive.cli._common.lock_output``). A second command writing the same target is
refused in one line naming it and the holder's pid (:class:`OutputError`, exit status 2).
Beside, not inside: a folder written as a whole is renamed into place from a temporary
sibling, which would carry a lock file inside it away (and a lock inside would be one more
file in the folder to tell apart from the results); the parent is never renamed, so the lock
outlives the swap. Missing parent folders are made for the lock (the command would make them
anyway) and removed again at the end if they are still empty. The lock file is removed when
the command ends, while still held; a taker checks that the file it locked is still the one
at that name (same inode), so a file removed under it is never shared. A process that dies
releases its lock with it (the kernel drops ``flock`` locks when the last descriptor closes:
the descriptor is close-on-exec, and workers are started from the fork server, not forked
from the command), and a lock file a killed command left behind is taken over by the next
one. Only where the parent takes no new files (``--out`` is a writable folder in a read-only
one) does the lock go inside the folder, as ``.persuasive.lock``; lock files never count as
results or as a user's files (:func:`is_lock_file`). A file system without ``flock`` support
leaves the command unlocked rather than failing it.

Every failure raises :class:`OutputError`, a :class:`~persuasive.config.ConfigError` whose
one-line message names the path the user gave and the reason, never a temporary name. The
reason is the true one where the operating system's is misleading: a folder on a virtual file
system (``/proc``, ``/sys``: the kernel answers "no such file or directory" even to root) is
named as such, before any work (:func:`unwritable_reason`).
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from .config import ConfigError


class OutputError(ConfigError):
    """An output that cannot be written; the message names the user's path and the reason."""


#: Where Linux lists the mounted file systems (device, mount point, type, ...).
MOUNTS = "/proc/self/mounts"
#: File systems made up by the kernel: they hold no files a program creates, whatever the
#: permissions say (root may "write" to /proc, and gets ENOENT or EACCES).
VIRTUAL_FILE_SYSTEMS = frozenset({
    "proc", "sysfs", "cgroup", "cgroup2", "debugfs", "tracefs", "securityfs", "pstore", "bpf",
    "configfs", "fusectl", "efivarfs", "binfmt_misc", "devpts", "mqueue", "nsfs", "autofs",
    "rpc_pipefs", "selinuxfs"})


def _unescape_mount(field: str) -> str:
    # /proc/self/mounts writes a space, tab, newline and backslash as octal escapes
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), field)


def mount_type(path: str | Path) -> str | None:
    """The type of the file system holding ``path`` (e.g. ``"proc"``), from :data:`MOUNTS`;
    ``None`` where that cannot be read (not Linux)."""
    try:
        with open(MOUNTS, encoding="utf-8", errors="replace") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None
    target = os.path.realpath(path)
    best, kind = -1, None
    for line in lines:
        parts = line.split()
        if len(parts) < 3:
            continue
        mount = _unescape_mount(parts[1])
        inside = target == mount or target.startswith(mount.rstrip("/") + "/")
        if inside and len(mount) >= best:  # the deepest mount wins (later ones over earlier)
            best, kind = len(mount), parts[2]
    return kind


def unwritable_reason(folder: str | Path) -> str | None:
    """Why new files cannot be made in the existing ``folder``, or ``None`` when they can (as
    far as can be told before trying): a virtual file system, or no write permission."""
    folder = Path(folder)
    kind = mount_type(folder)
    if kind in VIRTUAL_FILE_SYSTEMS:
        return (f"{str(folder)!r} is on a virtual file system ({kind}) that cannot hold "
                "result files")
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{str(folder)!r} is not writable"
    return None


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        if exc.errno is not None:
            return os.strerror(exc.errno).lower()
        return str(exc.strerror or exc).lower()
    text = str(exc).strip().splitlines()
    return text[0] if text else exc.__class__.__name__


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output_file(path: str | Path, allowed: Sequence[str], what: str = "output") -> str:
    """Check a file target before any work; return its lower-case extension.

    Raises :class:`OutputError` when the extension is not in ``allowed``, the parent folder
    does not exist, is not a folder or takes no new files (:func:`unwritable_reason`), or
    ``path`` is an existing folder.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in allowed:
        raise OutputError(f"{what} file {str(path)!r} has an unsupported extension "
                          f"{ext or '(none)'!r}; allowed: {' | '.join(allowed)}")
    parent = path.parent
    if not parent.exists():
        raise OutputError(f"{what} file {str(path)!r} cannot be written: folder "
                          f"{str(parent)!r} does not exist (create it first)")
    if not parent.is_dir():
        raise OutputError(f"{what} file {str(path)!r} cannot be written: {str(parent)!r} "
                          "is not a folder")
    if path.is_dir():
        raise OutputError(f"{what} file {str(path)!r} cannot be written: it is a folder")
    why = unwritable_reason(parent)
    if why:  # worded as when the write itself fails (atomic_write), for the same cause
        raise OutputError(f"cannot write {str(path)!r}: {why}")
    return ext


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Write ``path`` through ``write(tmp)`` on a unique temporary sibling, then rename it.

    The temporary name keeps the extension, so writers can infer the format from it. The
    parent folder must exist. Any failure (of ``write`` or of the file system) raises
    :class:`OutputError` naming ``path``; ``path`` is left as it was.
    """
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}",
                                    dir=path.parent)
    except OSError as exc:
        why = unwritable_reason(path.parent) if path.parent.is_dir() else None
        raise OutputError(f"cannot write {str(path)!r}: {why or _reason(exc)}") from None
    os.close(fd)
    tmp = Path(name)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; results are not
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OutputError:
        raise
    except Exception as exc:  # noqa: BLE001 - any writer failure becomes one line
        raise OutputError(f"cannot write {str(path)!r}: {_reason(exc)}") from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return path


def check_output_folder(path: str | Path, what: str = "results folder") -> Path:
    """Check a folder target: it may exist (as a folder) or not; its nearest existing folder
    (itself when it exists) must take new files (:func:`unwritable_reason`)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{what} {str(path)!r} cannot be written: it is a file")
    for folder in (path, *path.parents):
        if folder.exists():
            if not folder.is_dir():
                raise OutputError(f"{what} {str(path)!r} cannot be written: {str(folder)!r} "
                                  "is not a folder")
            why = unwritable_reason(folder)
            if why:
                raise OutputError(f"{what} {str(path)!r} cannot be written: {why}")
            break
    return path


#: The lock file of :func:`writer_lock` inside a folder (only where its parent takes no files).
INSIDE_LOCK = ".persuasive.lock"
#: What a writer lock's file is called beside its target: ``.<name>`` + this.
LOCK_SUFFIX = ".persuasive.lock"
_LOCK_NAME = re.compile(r"\.(?:.+\.)?persuasive\.lock")


def is_lock_file(name: str) -> bool:
    """Whether ``name`` is the name of a :func:`writer_lock` file (``.persuasive.lock``,
    ``.<target>.persuasive.lock``): neither a result nor a user's file."""
    return _LOCK_NAME.fullmatch(name) is not None


def owns(name: str, owned: Sequence[str]) -> bool:
    """Whether a top-level file ``name`` is one a command writes: it matches one of the glob
    patterns ``owned`` (see the module docstring)."""
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in owned)


def folder_entries(path: str | Path, owned: Sequence[str]) -> tuple[list[str], list[str],
                                                                     list[str]]:
    """The entries of the existing folder ``path``, sorted, in three lists: the command's own
    files (regular files whose names match ``owned``), lock files (:func:`is_lock_file`) and
    the others (a user's files, subfolders: never deleted, see the module docstring)."""
    own, locks, other = [], [], []
    for child in sorted(Path(path).iterdir()):
        if is_lock_file(child.name):
            locks.append(child.name)
        elif owns(child.name, owned) and child.is_file() and not child.is_symlink():
            own.append(child.name)
        else:
            other.append(child.name + ("/" if child.is_dir() else ""))
    return own, locks, other


def check_replaceable_folder(path: str | Path, force: bool = False,
                             what: str = "results folder",
                             owned: Sequence[str] = ()) -> Path:
    """Check, before any work, a folder that a command writes as a whole
    (:func:`atomic_folder` with the same ``owned``): :func:`check_output_folder`, and it must
    not hold the current folder (it could not be replaced) nor, without ``force``, any entry
    but lock files (the message names the folder and one entry: another file first, else
    one of the command's earlier results). With ``force`` the command's own files will be
    replaced and every other entry kept."""
    path = check_output_folder(path, what)
    here = Path.cwd().resolve()
    if path.exists() and path.resolve() in (here, *here.parents):
        raise OutputError(f"{what} {str(path)!r} cannot be replaced: it holds the current "
                          "folder; name a new or empty folder")
    if not force and path.is_dir():
        own, _, other = folder_entries(path, owned)
        if other:
            raise OutputError(f"{what} {str(path)!r} holds other files ({other[0]}); choose "
                              "another --out, or pass --force to replace only this command's "
                              "own files in it (the others are kept)")
        if own:
            raise OutputError(f"{what} {str(path)!r} holds earlier results ({own[0]}); "
                              "choose another --out or pass --force to replace them")
    return path


def _merge(tmp: Path, path: Path, owned: Sequence[str], what: str) -> None:
    """Move every file of ``tmp`` into the existing folder ``path`` (one ``os.replace``
    each), then remove the files of ``owned`` names that the new set lacks; nothing else in
    ``path`` is touched."""
    new = sorted(child.name for child in tmp.iterdir())
    own, _, _ = folder_entries(path, owned)
    for name in new:  # refused before anything moves: a name the command does not own
        target = path / name
        if (target.exists() or target.is_symlink()) and name not in own:
            raise OutputError(f"{what} {str(path)!r} holds {name!r}, which this command did "
                              "not write; move it or choose another --out")
    for name in new:
        os.replace(tmp / name, path / name)
    for name in set(own) - set(new):
        (path / name).unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_folder(path: str | Path, what: str = "results folder",
                  owned: Sequence[str] = ()) -> Iterator[Path]:
    """Yield a temporary folder for a command's files; on success they replace the command's
    earlier files in ``path`` (see the module docstring).

    Files are written into a hidden sibling of ``path``, then fsynced. A new ``path``, or
    one that holds only files matching the glob patterns ``owned``, is then replaced as a
    whole: the old one renamed aside, the new one renamed into place, the old one removed.
    A ``path`` holding anything else (a user's file, a subfolder, a lock file) keeps it: each
    new file is renamed into place, then the ``owned`` files the new set lacks are removed.
    With ``owned`` empty nothing in an existing ``path`` is the command's, and nothing is
    removed. On error the temporary folder is removed and ``path`` is untouched.
    """
    path = Path(path)
    check_output_folder(path, what)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes it private; results are not
    except OSError as exc:
        why = unwritable_reason(path.parent) if path.parent.is_dir() else None
        raise OutputError(f"{what} {str(path)!r} cannot be written: "
                          f"{why or _reason(exc)}") from None
    try:
        yield tmp
        for child in tmp.iterdir():
            if child.is_file():
                with open(child, "rb") as fh:
                    os.fsync(fh.fileno())
        if path.is_dir():
            _, locks, other = folder_entries(path, owned)
            if locks or other:
                _merge(tmp, path, owned, what)
                return
        old = None
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old",
                                        dir=path.parent))
            os.replace(path, old / path.name)
        os.replace(tmp, path)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except OutputError:
        raise
    except OSError as exc:
        if exc.errno == errno.ENOTEMPTY:
            raise OutputError(f"{what} {str(path)!r} cannot be replaced: {_reason(exc)}") \
                from None
        raise OutputError(f"{what} {str(path)!r} cannot be written: {_reason(exc)}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# -- one writer per target -----------------------------------------------------------------


def _make_folders(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; return those made, outermost first."""
    missing = []
    for f in (folder, *folder.parents):
        if f.exists():
            break
        missing.append(f)
    folder.mkdir(parents=True, exist_ok=True)
    return missing[::-1]


def _remove_empty(folders: list[Path]) -> None:
    for f in reversed(folders):  # innermost first; one that holds anything stays
        try:
            f.rmdir()
        except OSError:
            return


def _holder(lock: Path) -> str:
    """``" (pid N)"`` of the process a lock file names, or nothing when it names none yet."""
    try:
        text = lock.read_text(encoding="ascii", errors="replace").split()
    except OSError:
        return ""
    return f" (pid {text[0]})" if text and text[0].isdigit() else ""


def _lock_file(target: Path, what: str, shown: str) -> Path:
    """Where the lock of ``target`` lives: beside it, or inside an existing folder whose
    parent takes no new files (the module docstring)."""
    parent = Path(os.path.realpath(target.parent))
    if not target.name:  # the root folder has no parent to hold it
        return parent / INSIDE_LOCK
    if os.access(parent, os.W_OK | os.X_OK):
        return parent / f".{target.name}{LOCK_SUFFIX}"
    if target.is_dir() and not target.is_symlink() and os.access(target, os.W_OK | os.X_OK):
        return Path(os.path.realpath(target)) / INSIDE_LOCK
    why = unwritable_reason(parent) or f"{str(parent)!r} is not writable"
    raise OutputError(f"{what} {shown!r} cannot be written: {why}")


def _open_lock(lock: Path) -> int:
    try:
        return os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
    except PermissionError:  # another user's lock file: flock needs no write access
        return os.open(lock, os.O_RDONLY | os.O_CLOEXEC)


@contextlib.contextmanager
def writer_lock(path: str | Path, what: str = "output") -> Iterator[Path]:
    """Hold the one-writer lock of the file or folder ``path`` (the module docstring) for the
    block; yield the lock file's path.

    Raises :class:`OutputError` (``"<what> '<path>' is being written by another persuasive
    command (pid N); wait until it ends or write elsewhere"``) at once when another holder,
    in this process or another, has it; nothing is written then. Missing parent folders of
    ``path`` are made, and removed at the end if still empty. The lock file is removed at
    the end, while still held.
    """
    shown = str(path)
    try:
        import fcntl
    except ImportError:  # not POSIX: no advisory locks to take
        yield Path(path)
        return
    target = Path(os.path.abspath(path))
    made: list[Path] = []
    fd = None
    try:
        for _ in range(1000):  # a releasing holder may remove the file, or the folders, between
            try:
                made += [f for f in _make_folders(target.parent) if f not in made]
                lock = _lock_file(target, what, shown)
                fd = _open_lock(lock)
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise OutputError(f"{what} {shown!r} cannot be written: "
                                  f"{_reason(exc)}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                fd = None
                raise OutputError(f"{what} {shown!r} is being written by another persuasive "
                                  f"command{_holder(lock)}; wait until it ends or write "
                                  "elsewhere") from None
            except OSError:  # a file system without flock: go on unlocked
                os.close(fd)
                fd = None
                break
            try:  # still the file at that name? (a holder removes it before letting go)
                same = os.stat(lock).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                with contextlib.suppress(OSError):  # the pid is for messages only
                    os.ftruncate(fd, 0)
                    os.write(fd, f"{os.getpid()}\n".encode("ascii"))
                break
            os.close(fd)
            fd = None
        else:
            raise OutputError(f"{what} {shown!r} cannot be locked: its lock file keeps "
                              "changing")
        yield lock if fd is not None else target
    finally:
        if fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(lock)
            os.close(fd)
        _remove_empty(made)

def json_safe(value: Any) -> Any:
    """``value`` with NumPy scalars as Python values and every non-finite float as None, so
    that ``json.dumps(..., allow_nan=False)`` writes it (JSON has no NaN)."""
    import math

    import numpy as np

    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return None if not math.isfinite(value) else float(value)
    return value
