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
one-line message names the path the user gave and the reason, never a temporary name.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator, Sequence

from .config import ConfigError


class OutputError(ConfigError):
    """An output that cannot be written; the message names the user's path and the reason."""


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
    does not exist or is not a folder, or ``path`` is an existing folder.
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
        raise OutputError(f"cannot write {str(path)!r}: {_reason(exc)}") from None
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
    """Check a folder target: it may exist (as a folder) or not; its parent must be creatable."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{what} {str(path)!r} cannot be written: it is a file")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{what} {str(path)!r} cannot be written: {str(parent)!r} "
                                  "is not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise OutputError(f"{what} {str(path)!r} cannot be written: "
                                  f"{str(parent)!r} is not writable")
            break
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
        raise OutputError(f"{what} {str(path)!r} cannot be written: {_reason(exc)}") from None
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
