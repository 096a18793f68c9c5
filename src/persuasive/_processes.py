"""Worker processes that never fork a threaded process and never outlive the command.

**Why a fork server.** A process that runs threads (Dask's event loop and process watchers,
tqdm's monitor, a BLAS pool) must not be forked: the child inherits every lock in the state
it had at the fork, held by threads that do not exist in the child, and can wait on one for
ever. (A 16-core machine hung in ``persuasive reproduce all`` exactly so: the second table's
workers were forked from a command that already ran the first table's threads.) So the
worker processes of the local Dask cluster (:mod:`persuasive.sweep`) and of the SUMO study
are started from a *fork server* (:func:`context`): a fresh interpreter, started by fork and
exec (safe from any thread), that loads the package and its compiled kernels once, stays
single-threaded (:data:`SERVER_ENV` keeps BLAS and pyarrow's allocator from starting
threads in it) and forks each worker on request. A worker therefore starts with the kernels
loaded, as a forked one did, without inheriting the command's threads. Where the platform
has no fork server (Windows), workers are spawned.

**How workers die with the command.** Every link is tied by the kernel, not by a watcher
that could miss the moment (:mod:`persuasive._forkserver` does the server's side):

- command -> server: the server asks the kernel for SIGTERM when the thread that started it
  ends (``prctl(PR_SET_PDEATHSIG)``), then checks that its parent is still the command (it
  may have died before the call). That thread is a daemon thread of this module, idle for
  the life of the command, so it ends only when the command does. On SIGTERM the server
  kills its workers, waits for them, removes the command's scratch folder and exits.
- server -> worker: every worker asks for SIGKILL on the server's death in its first step
  after the fork (an ``os.register_at_fork`` hook installed in the server, run before the
  worker can block on anything), then checks that its parent is still the server.

Dask's own tie (a pipe whose closing ends the worker) stays as a second line.

**The command's script is not run again.** A worker started by spawn or a fork server runs
the command's ``__main__`` script again before its task (Python's rule), so a script that
calls a sweep at its top level without ``if __name__ == "__main__":`` would start sweeps in
its workers. The workers run only the package's own functions (and Dask sends a script's
own functions by value), so the fork server presents the command's ``__main__`` as already
loaded and they skip it: a script needs no guard, as with fork. A process pool of your own
whose tasks are functions of your script should use the ``spawn`` context instead (the
benchmark scripts do).

**Scratch.** A command's temporary folders (Dask's worker folders, SUMO's network and
episode files, a reproduction's sweep folders when no ``--out`` is given) live in one
scratch folder per command (:func:`scratch_root`) under the temporary folder (``TMPDIR``):
each user removes its own folder when done, the command removes the scratch folder when it
exits, and the fork server removes it when the command is killed.
"""

from __future__ import annotations

import atexit
import json
import multiprocessing
import os
import queue
import shutil
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

#: Modules the fork server imports before it forks anything.
PRELOAD = ("persuasive._forkserver",)
#: Tells the fork server which process started it (the command) [pid].
PARENT_ENV = "PERSUASIVE_FORKSERVER_PARENT"
#: Names the command's scratch folder to the fork server and to the workers.
SCRATCH_ENV = "PERSUASIVE_SCRATCH"
#: Names the command's main script or module to the fork server (JSON: path, name).
MAIN_ENV = "PERSUASIVE_FORKSERVER_MAIN"
#: The fork server's environment (inherited by its workers), set only while it starts: one
#: thread each. OpenBLAS would start a pool at numpy's import, pyarrow's jemalloc a
#: background thread; the workers run one compiled kernel at a time.
SERVER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "JE_ARROW_MALLOC_CONF": "background_thread:false"}

_lock = threading.RLock()
_scratch: Path | None = None
_scratch_owner = 0
_jobs: queue.SimpleQueue | None = None
_jobs_pid = 0


def start_method() -> str:
    """``forkserver`` where the platform has one (Linux, macOS), else ``spawn``."""
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


def scratch_root() -> Path:
    """This command's scratch folder (created on first use; see the module docstring).

    In a worker it is the command's (named by :data:`SCRATCH_ENV`), so what a worker leaves
    there is removed with the command's.
    """
    global _scratch, _scratch_owner
    inherited = os.environ.get(SCRATCH_ENV)
    if inherited and Path(inherited).is_dir():
        return Path(inherited)
    with _lock:
        if _scratch is None or not _scratch.is_dir():
            _scratch, _scratch_owner = Path(tempfile.mkdtemp(prefix="persuasive-")), os.getpid()
            atexit.register(_remove_scratch, _scratch, _scratch_owner)
        return _scratch


def _remove_scratch(folder: Path, owner: int) -> None:
    if os.getpid() == owner:  # not in a child that inherited the exit handler
        shutil.rmtree(folder, ignore_errors=True)


def remove_scratch() -> None:
    """Remove this command's scratch folder now (before an immediate exit)."""
    with _lock:
        if _scratch is not None:
            _remove_scratch(_scratch, _scratch_owner)


def scratch_dir(prefix: str) -> Path:
    """A new folder in :func:`scratch_root`; the caller removes it when done."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=scratch_root()))


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (read from ``/proc``; none where there is no
    ``/proc``)."""
    kids = []
    for entry in os.listdir("/proc") if os.path.isdir("/proc") else ():
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", "rb") as fh:
                    ppid = int(fh.read().rsplit(b")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            if ppid == pid:
                kids.append(int(entry))
    return kids


def descendants(pid: int) -> list[int]:
    """Every process below ``pid``: its children, theirs, and so on."""
    kids = children(pid)
    return kids + [d for k in kids for d in descendants(k)]


def _keeper(fn: Callable[[], Any]) -> Any:
    """Run ``fn`` in this module's daemon thread, which lives as long as the process: the
    fork server's parent-death signal is tied to the thread that starts it."""
    global _jobs, _jobs_pid
    with _lock:
        if _jobs is None or _jobs_pid != os.getpid():  # a forked child has no keeper thread
            _jobs, _jobs_pid = queue.SimpleQueue(), os.getpid()
            threading.Thread(target=_keep, args=(_jobs,), name="persuasive-forkserver-parent",
                             daemon=True).start()
        box: list = []
        done = threading.Event()
        _jobs.put((fn, box, done))
    done.wait()
    ok, value = box[0]
    if not ok:
        raise value
    return value


def _keep(jobs: queue.SimpleQueue) -> None:
    while True:
        fn, box, done = jobs.get()
        try:
            box.append((True, fn()))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            box.append((False, exc))
        done.set()


#: The longest path a Unix socket may have here (``sun_path`` holds 108 bytes on Linux, 104 on
#: macOS, the final NUL included).
_SOCKET_PATH_MAX = 103
#: What multiprocessing adds to its folder for the fork server's socket:
#: ``/pymp-<8 characters>/listener-<8 characters>``.
_SOCKET_SUFFIX = 32


def _short_socket_folder() -> None:
    """Give multiprocessing a short folder for the fork server's socket when the temporary
    folder's path is too long for one (a deep ``TMPDIR``: "AF_UNIX path too long"). The
    folder is a ``pymp-`` folder in ``/tmp``, removed at exit, or by the fork server when the
    command is killed, as multiprocessing's own would be."""
    from multiprocessing import process

    config = process.current_process()._config  # noqa: SLF001 - where get_temp_dir looks
    if "tempdir" in config or len(tempfile.gettempdir()) + _SOCKET_SUFFIX <= _SOCKET_PATH_MAX:
        return
    short = Path(tempfile.mkdtemp(prefix="pymp-", dir="/tmp"))
    config["tempdir"] = str(short)
    atexit.register(_remove_scratch, short, os.getpid())


def _start_server(scratch: Path) -> int:
    """Start the fork server unless it runs (in the keeper thread, which runs one job at a
    time); its pid."""
    from multiprocessing import forkserver, spawn

    _short_socket_folder()
    forkserver.set_forkserver_preload(list(PRELOAD))
    data = spawn.get_preparation_data("persuasive-worker")
    main = {"path": data.get("init_main_from_path"), "name": data.get("init_main_from_name")}
    env = {**SERVER_ENV, PARENT_ENV: str(os.getpid()), SCRATCH_ENV: str(scratch),
           MAIN_ENV: json.dumps(main)}
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # fork + exec copies this process's environment
    try:
        forkserver.ensure_running()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return forkserver._forkserver._forkserver_pid  # noqa: SLF001 - no public accessor


def context() -> multiprocessing.context.BaseContext:
    """The multiprocessing context of every worker pool: the fork server (started once per
    command, see the module docstring), or spawn where there is none."""
    method = start_method()
    if method == "forkserver":
        scratch = scratch_root()
        _keeper(lambda: _start_server(scratch))
    return multiprocessing.get_context(method)


def server_pid() -> int | None:
    """The running fork server's pid (None before :func:`context` started one)."""
    from multiprocessing import forkserver

    return getattr(forkserver._forkserver, "_forkserver_pid", None)  # noqa: SLF001


__all__ = ["PRELOAD", "SERVER_ENV", "children", "context", "descendants", "remove_scratch", "scratch_dir", "scratch_root",
           "server_pid", "start_method"]
