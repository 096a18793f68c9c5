"""Running a sweep on Dask: a local cluster of worker processes, or any Dask scheduler.

The client (this process) validates the grid, checks the folder (:class:`SweepStore`), starts
or reaches the cluster, and only then writes into the folder (a sweep that cannot start leaves
nothing behind). It keeps a bounded number of chunks in flight (twice the cluster's threads):
each finished chunk comes back as the bytes of its Parquet part plus its failure records, is
written at once and dropped, and the next chunk is submitted (``distributed.as_completed``).
The client never holds more than those few chunks, whatever the number of runs, and the
workers need no shared file system: only the client writes.

By default a :class:`distributed.LocalCluster` is started with ``workers`` processes of one
thread each (the compiled kernels hold the GIL, so threads would not run in parallel), on
127.0.0.1 only, no dashboard, no profiler, quiet logs. The kernels are compiled (once) and
loaded in this process first; the workers are started from a fork server that has them loaded
(:func:`start_method`, :mod:`persuasive._processes`), never forked from this process, which
runs threads by then (a forked child can inherit a lock another thread held, and hang), and
they die with it. Dask's temporary files go to the command's scratch folder. ``scheduler`` connects
to a running scheduler instead (``dask scheduler`` / ``dask worker``), and ``client`` uses a
client you made (e.g. of a ``dask_jobqueue.SLURMCluster``). Every run is a pure function of
its configuration and seed, so the results do not depend on the cluster, the number of
workers or the order in which chunks finish.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from ..config import ConfigError
from .grid import Grid
from .records import _error_line, failure_record, run_pickled_chunk
from .store import Chunk, SweepStore, iter_failures, n_chunks

#: Chunks in flight per worker thread: one running, one queued, so no worker waits on the
#: client between chunks.
IN_FLIGHT_PER_THREAD = 2
#: How long to try to reach a scheduler given by address [s].
CONNECT_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class SweepSummary:
    """What a call of :func:`run` did."""

    folder: Path  #: the sweep folder
    grid_digest: str  #: identity of the grid (see :attr:`Grid.digest`)
    runs: int  #: runs in the grid
    chunks: int  #: chunks in the grid
    chunk: int  #: runs per chunk
    skipped: int  #: runs finished by an earlier call (their chunks were not run again)
    ran: int  #: runs computed by this call (failed ones included)
    failures: tuple[dict[str, Any], ...] = field(default=())  #: every failed run, in order
    workers: int = 0  #: worker threads of the cluster when the sweep started (0: none ran)
    wall_time_s: float = 0.0  #: time of this call [s]

    @property
    def ok(self) -> bool:
        """True when every run of the grid has finished without error."""
        return not self.failures

    @property
    def finished(self) -> int:
        """Runs of the grid that have a row in the dataset."""
        return self.runs - len(self.failures)

    def to_dict(self) -> dict[str, Any]:
        return {
            "folder": str(self.folder), "grid_digest": self.grid_digest, "runs": self.runs,
            "chunks": self.chunks, "chunk": self.chunk, "skipped": self.skipped,
            "ran": self.ran, "finished": self.finished, "failed": len(self.failures),
            "failures": list(self.failures), "workers": self.workers,
            "wall_time_s": self.wall_time_s,
        }


def _check_int(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{name} = {value!r} is out of range; allowed: integer >= 1")


@contextlib.contextmanager
def _quiet_logs() -> Iterator[None]:
    """Only errors from Dask's loggers while a sweep runs (restored afterwards)."""
    loggers = [logging.getLogger(name) for name in ("distributed", "dask")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(max(lg.getEffectiveLevel(), logging.ERROR))
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def start_method() -> str:
    """How the local cluster starts its worker processes: ``forkserver`` where the platform
    has one (Linux, macOS), else ``spawn`` (:func:`persuasive._processes.start_method`).

    Never ``fork``: this process runs threads (Dask's event loop, the process watchers of a
    cluster already closed, tqdm's monitor), and a forked child inherits their locks in the
    state they had, held by threads it does not have. ``reproduce all`` hung so on a 16-core
    machine. The fork server is a fresh, single-threaded interpreter that loads the package
    and its kernels once and forks each worker from itself, so workers still start with the
    kernels loaded (a spawned worker would load them itself: 1.5 to 2 s on 2 cores). Dask's
    ``distributed.worker.multiprocessing-method`` is not read: its default, ``spawn``, is slower
    and has no tie to this process; a cluster of your own (``scheduler``, ``client``) uses
    its own settings.
    """
    from .._processes import start_method as method

    return method()


def _warm_up(grid: Grid) -> None:
    """Load the compiled kernels here (compiling them once if they are not cached) so that
    forked workers inherit them, and so that workers never compile at the same time."""
    from .._compile import warm_up
    from ..simulation import simulate

    warm_up()
    try:  # the grid's own kind of run, in case it uses kernels warm_up does not
        config = grid.config(0)
        if config.scenario.kind == "junction":
            from ..many.world import warm_up as junction_warm_up

            junction_warm_up(config)
        else:
            simulate(config.with_overrides({"simulation.n_steps": 1}), grid.seed_start)
    except Exception:  # noqa: BLE001 - only a warm-up; the sweep reports real failures
        pass


@contextlib.contextmanager
def local_client(workers: int, method: str | None = None) -> Iterator[Any]:
    """A client of a new :class:`distributed.LocalCluster`: ``workers`` processes, one thread
    each, started by ``method`` (default :func:`start_method`; another only to show why it is
    the default), listening on 127.0.0.1 only, no dashboard, no profiler, quiet logs, its
    temporary files in the command's scratch folder; closed on exit (an exception or an
    interrupt in the block kills the workers first)."""
    import dask
    from distributed import Client, LocalCluster
    from distributed.utils import get_mp_context

    from .. import _processes

    method = method or start_method()
    scratch = _processes.scratch_dir("dask-")
    settings = {"distributed.worker.multiprocessing-method": method,
                "distributed.worker.profile.enabled": False,
                "temporary-directory": str(scratch)}
    cluster = None
    try:
        with dask.config.set(settings):
            if method == "forkserver":
                get_mp_context()  # Dask names its own preload once per process: before ours
                _processes.context()  # the fork server, with the kernels loaded
            # the scheduler's HTTP server (health checks only: no dashboard) on any free port
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=None,
                                   scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                   silence_logs=logging.ERROR)
        with Client(cluster, set_as_default=False) as client:
            pids = list(client.run(os.getpid).values())
            try:
                yield client
            except BaseException:
                # interrupted (Ctrl-C) or failed: end the workers' tasks now; a graceful
                # close would wait for them (seconds for a SUMO episode)
                for pid in pids:
                    with contextlib.suppress(OSError):
                        os.kill(pid, signal.SIGKILL)
                raise
    finally:
        if cluster is not None:
            cluster.close()
        shutil.rmtree(scratch, ignore_errors=True)


@contextlib.contextmanager
def remote_client(address: str) -> Iterator[Any]:
    """A client of the running scheduler at ``address`` (e.g. ``tcp://host:8786``)."""
    from distributed import Client

    try:
        client = Client(address, set_as_default=False, timeout=f"{CONNECT_TIMEOUT_S}s")
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"scheduler {address!r} cannot be reached: "
                          f"{_error_line(exc)}") from None
    with client:
        yield client


def map_bounded(client: Any, fn: Callable[[Any], Any], tasks: Sequence[Any],
                in_flight: int | None = None) -> Iterator[tuple[int, Any]]:
    """``(i, fn(tasks[i]))`` for every task, as each finishes on ``client``'s workers, with at
    most ``in_flight`` tasks submitted at once [:data:`IN_FLIGHT_PER_THREAD` per worker
    thread], so that any number of tasks takes bounded memory here. A task that raises
    raises here."""
    from distributed import as_completed

    limit = in_flight or IN_FLIGHT_PER_THREAD * max(1, _threads(client))
    queue = as_completed(loop=client.loop, with_results=False)
    index: dict[str, int] = {}
    todo = iter(enumerate(tasks))

    def submit_more() -> None:
        while len(index) < limit:
            item = next(todo, None)
            if item is None:
                return
            future = client.submit(fn, item[1], pure=False, retries=0)
            index[future.key] = item[0]
            queue.add(future)

    submit_more()
    for future in queue:
        i = index.pop(future.key)
        result = future.result()
        future.release()
        yield i, result
        submit_more()


def run_all(fn: Callable[[Any], Any], tasks: Sequence[Any], workers: int | None = None,
            progress: Callable[[int, int], None] | None = None) -> list[Any]:
    """``[fn(task) for task in tasks]``, in the tasks' order, on a new local cluster of
    ``workers`` processes (default: every core; at most one per task), through
    :func:`map_bounded`; ``progress(done, total)`` after each task."""
    import os

    k = min(workers or os.cpu_count() or 1, len(tasks))
    done: dict[int, Any] = {}
    with local_client(k) as client:  # workers from the fork server, tied to this process
        for i, out in map_bounded(client, fn, tasks):
            done[i] = out
            if progress is not None:
                progress(len(done), len(tasks))
    return [done[i] for i in range(len(tasks))]


def _threads(client: Any) -> int:
    return sum(client.nthreads().values())


def _execute(client: Any, grid: Grid, store: SweepStore, pending: Iterator[Chunk],
             progress: Callable[[int, int], None] | None, done: int) -> None:
    """Run ``pending`` on ``client``, writing each chunk as it finishes."""
    import pickle

    from distributed import as_completed

    total = len(grid)
    todo = iter(pending)
    in_flight: dict[str, Chunk] = {}
    queue = as_completed(loop=client.loop, with_results=False)
    digest, grid_pickle = grid.digest, pickle.dumps(grid)
    threads = {"n": _threads(client), "at": time.monotonic()}

    def submit_more() -> None:
        if time.monotonic() - threads["at"] > 1.0:  # workers may come and go
            threads["n"], threads["at"] = _threads(client), time.monotonic()
        while len(in_flight) < IN_FLIGHT_PER_THREAD * max(1, threads["n"]):
            chunk = next(todo, None)
            if chunk is None:
                return
            future = client.submit(run_pickled_chunk, digest, grid_pickle, chunk.start,
                                   chunk.stop, key=f"persuasive-sweep-{digest}-{chunk.id}",
                                   pure=False, retries=0)
            in_flight[future.key] = chunk
            queue.add(future)

    submit_more()
    for future in queue:
        chunk = in_flight.pop(future.key)
        try:
            part, failures = future.result()
        except Exception as exc:  # noqa: BLE001 - e.g. a worker died: the chunk is retried
            error = f"chunk failed: {_error_line(exc)}"
            part, failures = None, [failure_record(grid, i, error)
                                    for i in range(chunk.start, chunk.stop)]
        future.release()
        del future
        store.record(chunk, part, failures)
        done += chunk.size
        if progress is not None:
            progress(done, total)
        submit_more()


def pending_chunks(grid: Grid, out: str | Path, chunk: int | None = None, force: bool = False,
                   what: str = "sweep folder") -> int:
    """Chunks of ``grid`` that :func:`run` into ``out`` would run now (it checks the folder as
    :func:`run` does, and writes nothing)."""
    store = SweepStore.open(out, grid, chunk, force, what)
    todo, _ = store.pending()
    return n_chunks(todo, store.chunk) if todo else 0


@contextlib.contextmanager
def local_cluster(grids: Sequence[Grid], chunks: int,
                  workers: int | None = None) -> Iterator[Any]:
    """One local cluster (:func:`local_client`) for the sweeps of ``grids``, which have at
    most ``chunks`` chunks to run each: ``workers`` processes [all cores], never more than
    ``chunks``; ``None`` when there is nothing to run. The grids' kernels are compiled and
    loaded here first, so that the fork server loads them from the cache and the workers
    never compile them at the same time. Pass the client to :func:`run` (``client=``) for
    each grid: a command with several sweeps (``reproduce all``) starts one cluster."""
    if chunks <= 0:
        yield None
        return
    for grid in grids:
        _warm_up(grid)
    with _quiet_logs(), local_client(min(workers or os.cpu_count() or 1, chunks)) as client:
        yield client


def run(grid: Grid | str | Path, out: str | Path, workers: int | None = None,
        scheduler: str | None = None, client: Any = None, chunk: int | None = None,
        force: bool = False,
        progress: Callable[[int, int], None] | None = None,
        what: str = "sweep folder") -> SweepSummary:
    """Run every run of ``grid`` not yet in the sweep folder ``out``; see the module docstring.

    Parameters
    ----------
    grid : Grid or path
        The grid, or a grid TOML file.
    out : path
        The sweep folder (:mod:`persuasive.sweep.store` describes it). A folder holding the
        same sweep is resumed: finished chunks are skipped, chunks with failures rerun.
    workers : int, optional
        Processes of the local cluster [all cores, never more than the chunks to run].
        Not with ``scheduler`` or ``client``.
    scheduler : str, optional
        Address of a running Dask scheduler to use instead of a local cluster.
    client : distributed.Client, optional
        A client to use as it is (it is not closed).
    chunk : int, optional
        Runs per chunk (one Parquet part each) [about 32 chunks of 1 to 250 runs; when
        resuming, the folder's].
    force : bool
        Replace a folder holding another sweep (or other files) instead of refusing.
    progress : callable, optional
        ``progress(done_runs, total_runs)``, called once at the start and after every chunk.
    what : str
        How the caller names the folder in its messages (``"comparison folder"``, ...).

    Returns
    -------
    SweepSummary
        Counts, the failed runs (all of them, from this call or earlier ones) and the time.

    Raises
    ------
    ConfigError
        Bad arguments, an invalid grid, or a folder that cannot be used (before any run).
    """
    t0 = time.perf_counter()
    if not isinstance(grid, Grid):
        grid = Grid.from_toml(grid)
    if chunk is not None:
        _check_int("chunk", chunk)
    if workers is not None:
        _check_int("workers", workers)
    given = [name for name, v in (("workers", workers), ("scheduler", scheduler),
                                  ("client", client)) if v is not None]
    if len(given) > 1:
        raise ConfigError(f"{' and '.join(given)} exclude each other: workers sizes the local "
                          "cluster, scheduler or client name another one")
    store = SweepStore.open(out, grid, chunk, force, what)  # checks only, writes nothing
    todo, pending = store.pending()
    done = len(grid) - todo
    if progress is not None:
        progress(done, len(grid))
    threads = 0
    if todo:
        with _quiet_logs():
            if client is not None:
                context = contextlib.nullcontext(client)
            elif scheduler is not None:
                context = remote_client(scheduler)
            else:
                context = local_cluster([grid], n_chunks(todo, store.chunk), workers)
            with context as active:  # connected: only now is anything written
                store.start()
                threads = _threads(active)
                _execute(active, grid, store, pending, progress, done)
    return SweepSummary(folder=store.folder, grid_digest=grid.digest, runs=len(grid),
                        chunks=store.n_chunks, chunk=store.chunk, skipped=done, ran=todo,
                        failures=tuple(iter_failures(store.folder)), workers=threads,
                        wall_time_s=time.perf_counter() - t0)


__all__ = ["SweepSummary", "local_client", "local_cluster", "map_bounded", "pending_chunks",
           "run_all",
           "remote_client", "run", "start_method"]
