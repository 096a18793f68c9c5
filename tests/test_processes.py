"""Worker processes (persuasive._processes): never forked from a threaded process, tied to the
command on every link, their temporary files in the command's scratch folder.

The hang these guard against does not show on a 2-core machine by chance (it showed on a
16-core one); the tests make it certain instead: a thread of the command holds a lock of a
module the workers use while the cluster starts, and a worker's task then takes that lock. A
worker forked from the command inherits the lock held by a thread it does not have and waits
for ever; a worker of the fork server imports the module afresh and takes it at once. (A plain
lock: a reentrant one can slip through by chance, when the worker's thread gets the id of the
thread that held it.)
"""

from __future__ import annotations

import ctypes
import os
import re
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest

from persuasive import _processes
from persuasive._processes import descendants
from persuasive.sweep.runner import local_client, map_bounded

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="the parent-death signal and /proc are Linux's")

#: A module with a lock, used by the command and by the workers' task.
HELD = "import threading\nLOCK = threading.Lock()\n"

#: A command whose thread holds that lock while its cluster starts, and a task that takes it
#: in a worker: prints "took it" or "hung" (no answer in the time given).
LOCK_HELD = textwrap.dedent("""
    import os, sys, threading
    import held
    from persuasive.sweep.runner import local_client

    taken = threading.Event()

    def hold_for_ever():  # e.g. a thread filling a cache, for as long as the test runs
        with held.LOCK:
            taken.set()
            threading.Event().wait()

    def take_it(wait_s):
        import held
        return held.LOCK.acquire(timeout=wait_s)

    threading.Thread(target=hold_for_ever, daemon=True).start()
    taken.wait()
    method, wait_s = sys.argv[1], float(sys.argv[2])
    with local_client(1, method=method) as client:
        pids = list(client.run(os.getpid).values())
        if client.submit(take_it, wait_s, pure=False).result():
            print("took it", flush=True)
        else:
            print("hung", flush=True)
            for pid in pids:  # a forked worker has no tie to this process: end it here
                os.kill(pid, 9)
            os._exit(0)
""")


def _run_lock_held(tmp_path: Path, method: str, wait_s: float) -> str:
    script = tmp_path / "lock_held.py"
    script.write_text(LOCK_HELD)
    (tmp_path / "held.py").write_text(HELD)
    env = dict(os.environ, TMPDIR=str(tmp_path))
    run = subprocess.run([sys.executable, str(script), method, str(wait_s)], env=env,
                         capture_output=True, text=True, timeout=wait_s + 240)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout.strip().splitlines()[-1]


@pytest.mark.slow
def test_a_worker_forked_from_a_threaded_command_hangs(tmp_path):
    """The defect, shown with plain fork: the worker never gets the lock."""
    assert _run_lock_held(tmp_path, "fork", 8.0) == "hung"


@pytest.mark.slow
def test_a_worker_of_the_fork_server_does_not_inherit_the_commands_locks(tmp_path):
    """The fix: with the default start method (the fork server) the worker takes it at once."""
    assert _processes.start_method() == "forkserver"
    assert _run_lock_held(tmp_path, _processes.start_method(), 180.0) == "took it"


def _ppid(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _pdeathsig() -> int:
    sig = ctypes.c_int(0)
    ctypes.CDLL(None, use_errno=True).prctl(2, ctypes.byref(sig))  # PR_GET_PDEATHSIG
    return sig.value


def _square(x: int) -> int:
    return x * x


def test_workers_are_forked_by_a_single_threaded_server_and_tied_to_it():
    with local_client(2) as client:
        server = _processes.server_pid()
        assert server is not None and _ppid(server) == os.getpid()
        # the server runs one thread: nothing it forks can inherit a lock held by another
        assert os.listdir(f"/proc/{server}/task") == [str(server)]
        info = client.run(lambda: (os.getppid(), _pdeathsig(),
                                   signal.getsignal(signal.SIGTERM) == signal.SIG_DFL))
        assert sorted(info.values()) == [(server, signal.SIGKILL, True)] * 2
        # map_bounded: every task once, whatever the order they finish in
        got = dict(map_bounded(client, _square, list(range(9)), in_flight=2))
        assert got == {i: i * i for i in range(9)}


def test_workers_die_with_the_server(gone):
    with local_client(1) as client:
        (pid,) = client.run(os.getpid).values()
        server = _processes.server_pid()
        os.kill(server, signal.SIGKILL)
        assert gone(pid), "a worker outlived its fork server"


def test_scratch_is_per_command_and_inherited_by_workers():
    root = _processes.scratch_root()
    assert root.is_dir() and root.parent == Path(tempfile.gettempdir())
    mine = _processes.scratch_dir("x-")
    assert mine.parent == root
    with local_client(1) as client:
        (theirs,) = client.run(lambda: str(_processes.scratch_root())).values()
    assert Path(theirs) == root
    mine.rmdir()


@pytest.mark.slow
@pytest.mark.parametrize("group", [False, True], ids=["the command", "its process group"])
def test_a_killed_sweep_leaves_no_process_and_no_file_behind(tmp_path, kill_mid_run, gone,
                                                             group):
    """SIGKILL to the command, or to its whole process group (the fork server has a group
    of its own, so it outlives such a kill just long enough to clean up)."""
    runs = tmp_path / "r" / "runs"
    below, temp = kill_mid_run(
        ["reproduce", "table2", "--seeds", "400", "--workers", "2", "--quiet",
         "--out", str(tmp_path / "r")],
        lambda: runs.is_dir() and any(runs.glob("*.parquet")), group=group)
    assert len(below) >= 4
    assert all(gone(pid) for pid in below), "a process outlived the command"
    end = time.monotonic() + 10
    while any(temp.iterdir()) and time.monotonic() < end:
        time.sleep(0.05)
    assert list(temp.iterdir()) == []  # the fork server removed the command's scratch
    assert not (tmp_path / "r" / "summary.json").exists()


def _interrupt(tmp_path: Path, argv: list[str], ready, env_extra=None):
    """Start ``persuasive argv`` with a TMPDIR of its own, send it SIGINT (Ctrl-C) once
    ``ready(stderr_so_far)`` holds, and return (exit status, seconds to exit, stderr, the
    processes that were below it, its TMPDIR)."""
    temp = tmp_path / "int-tmp"
    temp.mkdir()
    env = dict(os.environ, TMPDIR=str(temp), **(env_extra or {}))
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "persuasive", *argv], env=env,
                                stdout=subprocess.DEVNULL, stderr=err)
        deadline = time.monotonic() + 240
        while proc.poll() is None and time.monotonic() < deadline:
            if ready(err_path.read_text()):
                break
            time.sleep(0.05)
        assert proc.poll() is None, ("the command ended before it was interrupted: "
                                     + err_path.read_text()[-1000:])
        below = descendants(proc.pid)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        finally:
            proc.kill()
        took = time.monotonic() - t0
    return proc.returncode, took, err_path.read_text(), below, temp


def _one_error_line(stderr: str) -> str:
    assert "Traceback" not in stderr, stderr
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, stderr
    return errors[0]


@pytest.mark.slow
def test_ctrl_c_during_a_kernel_compile_stops_at_once(tmp_path):
    """With an empty kernel cache the command compiles for many seconds; Ctrl-C there ends
    it at once (an interrupt raised inside the compile would be swallowed by LLVM's
    callbacks or end in a traceback), with the same line as anywhere else."""
    noticed: list[float] = []

    def compiling(err: str) -> bool:  # 3 s after the notice: inside the first compile
        if "compiling the numerical kernels" in err and not noticed:
            noticed.append(time.monotonic())
        return bool(noticed) and time.monotonic() - noticed[0] > 3.0

    code, took, err, _, temp = _interrupt(tmp_path, ["simulate", "--seed", "3"], compiling,
                                          {"NUMBA_CACHE_DIR": str(tmp_path / "empty-cache")})
    assert code == 130 and took < 5.0, (code, took)
    assert _one_error_line(err) == "error: interrupted"
    assert list(temp.iterdir()) == []


def _bar_moved(err: str) -> bool:
    """The progress bar counts at least one finished run (or seed)."""
    return any(int(done) > 0 for done in re.findall(r"(\d+)/\d+ \[", err))


@pytest.mark.slow
@pytest.mark.parametrize("argv", [
    ["reproduce", "table2", "--seeds", "1000", "--workers", "2"],
    ["sumo", "--episodes", "40", "--workers", "2", "--flow", "900"],
])
def test_ctrl_c_mid_study_stops_within_a_second_and_leaves_nothing(tmp_path, argv, gone):
    """Ctrl-C once the study's progress bar runs: exit 130 within a second (5 s on a loaded
    machine), one line, every worker gone, the scratch folder removed, no results folder."""
    out = tmp_path / "out"
    code, took, err, below, temp = _interrupt(tmp_path, [*argv, "--out", str(out)], _bar_moved)
    assert code == 130 and took < 5.0, (code, took, err[-500:])
    assert _one_error_line(err) == "error: interrupted"
    assert len(below) >= 4 and all(gone(pid) for pid in below)
    assert list(temp.iterdir()) == []
    assert not (out / "summary.json").exists() and not (out / "episodes.parquet").exists()


def test_a_deep_temporary_folder_still_gets_a_fork_server(tmp_path):
    """A TMPDIR too deep for a Unix socket's path (108 bytes) used to end every sweep with
    "af_unix path too long": the server's socket then goes to a short folder of its own,
    which the command removes at exit."""
    deep = tmp_path / ("d" * 60) / ("e" * 40)
    deep.mkdir(parents=True)
    code = ("import os, tempfile; from persuasive.sweep.runner import local_client\n"
            "with local_client(1) as c:\n"
            "    print(sorted(c.run(lambda: 6 * 7).values()))\n")
    run = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, TMPDIR=str(deep)),
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "[42]"
    assert list(deep.iterdir()) == []  # the scratch folder is gone with the command
