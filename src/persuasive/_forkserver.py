"""Imported by the fork server only (:mod:`persuasive._processes`), before it forks anything.

It ties the server to the command that started it (SIGTERM on the command's death, then a
check that the command is still its parent), ties every worker the server forks to the
server (SIGKILL on the server's death, set in the worker's first step after the fork, then a
check that the server is still its parent), cleans up after a killed command, and loads the
package and its compiled kernels so that workers start with them. Importing it anywhere else
would tie that process to its parent: only the fork server names it.
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import signal
import sys
import time
import types
from pathlib import Path

from ._processes import MAIN_ENV, PARENT_ENV, SCRATCH_ENV, children

_PR_SET_PDEATHSIG = 1
#: This process, the server; a worker (a process forked by it) is not one.
_SERVER = os.getpid()
_is_server = True
#: The command that started the server.
_COMMAND = int(os.environ.pop(PARENT_ENV, "") or os.getppid())
_SCRATCH = os.environ.get(SCRATCH_ENV)


def parent_death_signal(sig: int) -> None:
    """Ask the kernel for ``sig`` when the thread that made this process ends (Linux)."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(sig))
        except (OSError, AttributeError):
            pass


def _on_command_death(signum: int = signal.SIGTERM, frame=None) -> None:
    """The command is gone: kill the workers, wait for them, remove its scratch, exit."""
    kids = children(os.getpid())
    for pid in kids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    for pid in kids:
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:
            pass
    # the command's scratch, and the folder of this server's socket (the command's
    # multiprocessing folder, which the command would have removed at its exit)
    from multiprocessing import forkserver

    address = getattr(forkserver._forkserver, "_forkserver_address", None)  # noqa: SLF001
    folders = [_SCRATCH] if _SCRATCH else []
    if isinstance(address, str) and Path(address).parent.name.startswith("pymp-"):
        folders.append(str(Path(address).parent))
    for folder in folders:
        # a child of the dead command (e.g. SUMO's netconvert) may be dying beside us
        for _ in range(10):
            shutil.rmtree(folder, ignore_errors=True)
            if not Path(folder).exists():
                break
            time.sleep(0.05)
    os._exit(0)


def _in_worker() -> None:
    """Runs in a process forked by this one, first thing after the fork."""
    global _is_server
    if not _is_server:  # a worker forking: its child is not ours to tie
        return
    _is_server = False
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # Dask stops workers with SIGTERM
    parent_death_signal(signal.SIGKILL)
    if os.getppid() != _SERVER:  # the server died before the line above
        os._exit(1)


# A process group of its own: a signal to the command's group (a shell's kill -9 -PGID, a
# terminal's Ctrl-C) then reaches the command, not the server, which is left to clean up
# after it. Its workers are in this group too: a Ctrl-C reaches them through the command,
# which kills them at once.
os.setpgid(0, 0)
signal.signal(signal.SIGTERM, _on_command_death)
parent_death_signal(signal.SIGTERM)
if os.getppid() != _COMMAND:  # the command died before the line above
    _on_command_death()
os.register_at_fork(after_in_child=_in_worker)


def _present_main() -> None:
    """Make the command's ``__main__`` look loaded here, so that workers do not run the
    command's script again (multiprocessing.spawn.prepare skips a main whose ``__file__`` or
    ``__spec__.name`` is already the command's; see persuasive._processes)."""
    main = json.loads(os.environ.pop(MAIN_ENV, "{}") or "{}")
    module = sys.modules["__main__"]
    if main.get("path"):
        module.__file__ = main["path"]
    if main.get("name"):
        module.__spec__ = types.SimpleNamespace(name=main["name"])


_present_main()

# What every worker needs, loaded once here (the fork server imports no thread-starting
# module beyond these; SERVER_ENV keeps these single-threaded).
try:
    import distributed  # noqa: F401  (the local cluster's workers)
except ImportError:  # pragma: no cover - Dask is a dependency
    pass
import pandas  # noqa: E402,F401
import pyarrow.parquet  # noqa: E402,F401

from . import simulation  # noqa: E402,F401
from ._compile import kernels_cached, warm_up  # noqa: E402
from .sweep import records  # noqa: E402,F401

if kernels_cached():  # else the command compiles them first, and workers load them
    warm_up()
