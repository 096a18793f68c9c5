"""Many seeds of the junction, each with and without the AV, on worker processes
(docs/method.md §15.6).

:func:`run_seed` runs one seed twice (the AV's run and the reference without it, for the
delay it causes) and returns its row (``JunctionWorld.summary``) and the AV's
run's step times; :func:`run_study` runs seeds on the worker processes of a local Dask cluster
(``persuasive.sweep.runner``), rows in seed order, bit-identical whatever the number of
workers; :func:`aggregate` is the study's one-line summary.
"""

from __future__ import annotations

import math
import time
from typing import Callable, Sequence

import numpy as np

from ..config import Config
from .junction import JunctionSpec
from .world import JunctionWorld, run_summary, warm_up


def run_seed(config: Config, spec: JunctionSpec, seed: int) -> tuple[dict, np.ndarray]:
    """One seed's row and its closed-loop step times [ms] (module docstring)."""
    world = JunctionWorld(config, spec, seed)
    times = []
    clock = time.perf_counter_ns
    while True:
        t0 = clock()
        info = world.step()
        times.append((clock() - t0) * 1e-6)
        if info.done:
            break
    reference = JunctionWorld(config, spec, seed, with_av=False).run()
    step_ms = np.array(times)
    return world.summary(reference, step_ms), step_ms


def _task(args) -> tuple[dict, np.ndarray]:
    config, spec, seed = args
    return run_seed(Config.from_dict(config), spec, seed)


def run_study(config: Config, spec: JunctionSpec, seeds: Sequence[int], workers: int = 1,
              progress: Callable[[int, int], None] | None = None
              ) -> tuple[list[dict], np.ndarray]:
    """Every seed's row (in seed order) and all step times [ms] (module docstring)."""
    (got,) = run_cells([(config, spec)], seeds, workers, progress)
    return got


def run_cells(cells: Sequence[tuple[Config, JunctionSpec]], seeds: Sequence[int],
              workers: int = 1, progress: Callable[[int, int], None] | None = None
              ) -> list[tuple[list[dict], np.ndarray]]:
    """:func:`run_study` of several configurations on the same seeds, on one pool of
    workers: per cell, its rows in seed order and its step times [ms]."""
    seeds = [int(s) for s in seeds]
    tasks = [(c, sp, s) for c, sp in cells for s in seeds]
    out: dict[int, tuple[dict, np.ndarray]] = {}
    for config in {(c.av.kind, c.shield): c for c, _ in cells}.values():
        warm_up(config)  # once per kind of AV and shield: the kernels they load
    if workers <= 1 or len(tasks) <= 1:
        for n, (c, sp, s) in enumerate(tasks):
            out[n] = run_seed(c, sp, s)
            if progress is not None:
                progress(n + 1, len(tasks))
    else:
        from ..sweep.runner import local_client, map_bounded

        data = [(c.to_dict(), sp, s) for c, sp, s in tasks]
        with local_client(min(workers, len(tasks))) as client:
            for i, got in map_bounded(client, _task, data):
                out[i] = got
                if progress is not None:
                    progress(len(out), len(tasks))
    m = len(seeds)
    return [([out[c * m + i][0] for i in range(m)],
             np.concatenate([out[c * m + i][1] for i in range(m)])) for c in range(len(cells))]


def aggregate(rows: Sequence[dict], step_ms: np.ndarray) -> dict:
    """The study's summary: counts, rates and medians over its rows."""
    n = len(rows)

    def mean(key: str) -> float:
        vals = [r[key] for r in rows if r[key] is not None and math.isfinite(r[key])]
        return float(np.mean(vals)) if vals else math.nan

    def lowest(key: str) -> float:
        vals = [r[key] for r in rows if math.isfinite(r[key])]
        return float(min(vals)) if vals else math.nan

    return {
        "runs": n,
        "n_vehicles": rows[0]["n_vehicles"] if rows else 0,
        "av_through_pct": 100.0 * sum(r["av_through"] for r in rows) / max(n, 1),
        "av_first_pct": 100.0 * sum(r["av_first_conflicts"] for r in rows) / max(
            1, sum(r["av_conflicts_passed"] for r in rows)),
        "av_conflicts_passed": int(sum(r["av_conflicts_passed"] for r in rows)),
        "av_caused_collisions": int(sum(r["av_caused_collisions"] for r in rows)),
        "av_collisions": int(sum(r["av_collisions"] for r in rows)),
        "uncertified_steps": int(sum(r["uncertified_steps"] for r in rows)),
        "shield_overrides": int(sum(r["shield_overrides"] for r in rows)),
        "deadlock_runs": int(sum(r["deadlock"] for r in rows)),
        "av_in_deadlock_runs": int(sum(r["av_in_deadlock"] for r in rows)),
        "av_caused_deadlock_runs": int(sum(r["av_caused_deadlock"] for r in rows)),
        "av_blocking_runs": int(sum(r["av_inside_blocking_s"] > 0.0 for r in rows)),
        "av_inside_stood_runs": int(sum(r["av_inside_stood_s"] > 0.0 for r in rows)),
        "max_av_wait_s": float(max((r["av_wait_s"] for r in rows), default=math.nan)),
        "human_collisions": int(sum(r["human_collisions"] for r in rows)),
        "mean_av_delay_s": mean("av_delay_s"),
        "mean_caused_delay_s": mean("caused_delay_s"),
        "mean_av_wait_s": mean("av_wait_s"),
        "mean_wait_s": mean("mean_wait_s"),
        "median_throughput_veh_h": float(np.median([r["throughput_veh_h"] for r in rows]))
        if rows else math.nan,
        "min_pet_av_s": lowest("min_pet_av_s"),
        "min_gap_av_m": lowest("min_gap_av_m"),
        "step_ms_median": float(np.median(step_ms)) if step_ms.size else math.nan,
        "step_ms_p99": float(np.percentile(step_ms, 99)) if step_ms.size else math.nan,
    }


__all__ = ["aggregate", "run_cells", "run_seed", "run_study", "run_summary", "warm_up"]
