"""``persuasive bench --sweep``: a Dask sweep against the process pool of ``reproduce``.

Both paths run the same runs, those of the paper's Table 1 (the 2-LFG case, the HV starting
as leader, then as follower, seeds ``1..size/2``; the cheapest runs, so the sweep's own costs
weigh the most), with the same number of worker processes, each timed end to end (workers
started, every run done, results in hand; the sweep also writes its Parquet parts and
manifest). The process pool is :func:`persuasive.experiments.run_tables`; the sweep is
:func:`persuasive.sweep.run` on a fresh :class:`distributed.LocalCluster` into a temporary
folder. The grid is derived from Table 1's row configurations, so both paths run identical
configurations and seeds, and the results are compared run by run.

The client's memory is its resident set size (``psutil``), sampled every 10 ms while the
sweep runs, after an untimed sweep of 4 runs has loaded Dask, pandas and pyarrow; the
scheduler of the local cluster lives in the client process and is included. It should not
grow with the number of runs.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from typing import Any

from .sweep.grid import Grid
from .sweep.records import flatten

#: Outcome columns compared between the two paths.
_COMPARED = ("seed", "first_at_line", "first_at_conflict_point", "collision",
             "min_distance_m", "min_distance_to_line_m", "idx_end", "hv_role_changes",
             "av_role_changes")


def table1_grid(seeds: int) -> Grid:
    """Table 1's rows as a grid: the first row's configuration as the base, and one axis per
    field in which the rows differ (the HV's initial role)."""
    from .config import Config
    from .experiments import PUBLISHED

    configs = [row.config(Config()) for row in PUBLISHED["table1"]]
    flats = [flatten(c.to_dict()) for c in configs]
    differ = [k for k in flats[0] if any(f.get(k) != flats[0][k] for f in flats[1:])]
    axes = {k: [f[k] for f in flats] for k in differ}
    return Grid.from_dict({"seeds": seeds, "base": configs[0].to_dict(), "axes": axes})


class _PeakRSS:
    """The peak resident set size of this process while the block runs [bytes]."""

    def __init__(self, every_s: float = 0.01):
        import psutil

        self._proc = psutil.Process()
        self._every = every_s
        self.peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="persuasive-rss", daemon=True)

    def _watch(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, self._proc.memory_info().rss)
            self._stop.wait(self._every)

    def __enter__(self) -> _PeakRSS:
        self.peak = self._proc.memory_info().rss
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._proc.memory_info().rss)


def bench_sweep(sizes: tuple[int, ...] = (2000, 8000), workers: int = 2,
                chunk: int | None = None, repeats: int = 3) -> dict[str, Any]:
    """Throughput of a ``workers``-process Dask sweep and of the process pool, and the
    sweep client's peak memory, for each number of runs in ``sizes`` (even numbers).

    First the memory: one sweep of each size, in increasing order, the client's resident
    set sampled throughout. Then the throughput: for each size, the pool and the sweep
    alternately, ``repeats`` times each, the fastest time of each kept (the machine may be
    shared; the best time is the least disturbed one).

    Returns a dict: ``workers``, ``chunk`` (as given; ``None`` is the default,
    :func:`persuasive.sweep.store.default_chunk`), ``repeats`` and ``sizes``, one dict per
    size with ``runs``, ``pool_s``, ``pool_runs_per_s``, ``sweep_s``, ``sweep_runs_per_s``,
    ``ratio`` (sweep / pool throughput), ``sweep_chunk`` (runs per chunk used),
    ``client_rss_before_mb`` and ``client_peak_rss_mb`` (before and during its sweep) and
    ``same_results`` (the two paths' outcomes agree run by run); and ``ratio``, the
    throughput ratio at the largest size.
    """
    from ._compile import warm_up
    from .experiments import run_tables
    from .sweep.runner import run
    from .sweep.store import load

    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats = {repeats!r} must be an integer >= 1")
    for size in sizes:
        if isinstance(size, bool) or not isinstance(size, int) or size < 2 or size % 2:
            raise ValueError(f"size = {size!r} must be an even number >= 2 (two rows)")
    warm_up()  # both paths then start from loaded kernels
    out: dict[str, Any] = {"workers": workers, "chunk": chunk, "repeats": repeats,
                           "sizes": []}
    with tempfile.TemporaryDirectory(prefix="persuasive-bench-sweep-") as tmp:
        # Dask, pandas and pyarrow loaded here, so that they do not count as the sweeps'
        run(table1_grid(2), os.path.join(tmp, "warm-up"), workers=workers)
        load(os.path.join(tmp, "warm-up"))
        memory = []
        for size in sizes:
            with _PeakRSS() as rss:
                before = rss.peak
                run(table1_grid(size // 2), os.path.join(tmp, f"memory-{size}"),
                    workers=workers, chunk=chunk)
            memory.append((before, rss.peak))
        for size, (before, peak) in zip(sizes, memory):
            grid = table1_grid(size // 2)
            pool_s, sweep_s = [], []
            for i in range(repeats):
                t = time.perf_counter()
                pool_runs = run_tables(["table1"], size // 2, workers)
                pool_s.append(time.perf_counter() - t)
                folder = os.path.join(tmp, f"sweep-{size}-{i}")
                t = time.perf_counter()
                summary = run(grid, folder, workers=workers, chunk=chunk)
                sweep_s.append(time.perf_counter() - t)
                if i == 0:
                    frame = load(folder, columns=list(_COMPARED))
                    same = summary.ok and len(frame) == size and all(
                        frame[c].tolist() == [r[c] for r in pool_runs] for c in _COMPARED)
                    del frame
                del pool_runs
            best_pool, best_sweep = min(pool_s), min(sweep_s)
            out["sizes"].append({
                "runs": size,
                "pool_s": best_pool,
                "pool_runs_per_s": size / best_pool,
                "sweep_s": best_sweep,
                "sweep_runs_per_s": size / best_sweep,
                "ratio": best_pool / best_sweep,
                "sweep_chunk": summary.chunk,
                "client_rss_before_mb": before / 2**20,
                "client_peak_rss_mb": peak / 2**20,
                "same_results": bool(same),
            })
    out["ratio"] = out["sizes"][-1]["ratio"]
    return out


__all__ = ["bench_sweep", "table1_grid"]
