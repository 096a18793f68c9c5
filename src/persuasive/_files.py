"""Writing result files and folders atomically, with one-line errors that name the user's path.

- :func:`check_output_file` checks a file target before any work: a known extension, an
  existing parent folder that is a folder (missing folders are *not* created for a file
  target), and no folder in the way.
- :func:`atomic_write` writes a file through a unique temporary sibling (``mkstemp`` in the
  target folder, so two threads or processes never share one), fsyncs it, then renames it
  into place; a failure leaves the target as it was and removes the temporary file.
- :func:`atomic_folder` writes a whole results folder as a set: every file into a temporary
  sibling folder, then one rename (an existing folder is swapped out and removed only after
  the new one is in place).

Every failure raises :class:`OutputError`, a :class:`~persuasive.config.ConfigError` whose
one-line message names the path the user gave and the reason, never a temporary name. The
reason is the true one where the operating system's is misleading: a folder on a virtual file
system (``/proc``, ``/sys``: the kernel answers "no such file or directory" even to root) is
named as such, before any work (:func:`unwritable_reason`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator, Sequence

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


def check_replaceable_folder(path: str | Path, force: bool = False,
                             what: str = "results folder") -> Path:
    """Check, before any work, a folder that a command writes as a whole (replacing it):
    :func:`check_output_folder`, and it must not hold the current folder (it could not be
    replaced) nor, without ``force``, any file (which the command would delete)."""
    path = check_output_folder(path, what)
    here = Path.cwd().resolve()
    if path.exists() and path.resolve() in (here, *here.parents):
        raise OutputError(f"{what} {str(path)!r} cannot be replaced: it holds the current "
                          "folder; name a new or empty folder")
    if not force and path.is_dir() and any(path.iterdir()):
        raise OutputError(f"{what} {str(path)!r} holds other files; choose another --out or "
                          "pass --force to replace it")
    return path


@contextlib.contextmanager
def atomic_folder(path: str | Path, what: str = "results folder") -> Iterator[Path]:
    """Yield a temporary folder; on success it replaces ``path`` as a whole.

    Files are written into a hidden sibling of ``path``; when the block ends without error,
    the sibling is fsynced and renamed to ``path`` (an existing ``path`` is first renamed
    aside, then removed). On error the temporary folder is removed and ``path`` is untouched.
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
