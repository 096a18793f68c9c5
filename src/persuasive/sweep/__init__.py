"""Parameter sweeps at scale on Dask (issue 11): a grid of configurations times seeds.

- :mod:`~persuasive.sweep.grid`: :class:`Grid`, the grid file (``seeds``, ``[base]``,
  ``[axes]``), validated whole before anything runs; :meth:`Grid.runs` in a fixed order.
- :mod:`~persuasive.sweep.records`: a chunk of runs as one Parquet part, the summaries
  flattened (:func:`flatten` / :func:`unflatten`), failed runs as records.
- :mod:`~persuasive.sweep.store`: the sweep folder (manifest, parts, failure files), resuming,
  :func:`load` and :func:`load_failures`.
- :mod:`~persuasive.sweep.runner`: :func:`run` on a local Dask cluster or any scheduler,
  with a bounded number of chunks in flight.
- :mod:`~persuasive.sweep.metrics`: :func:`metric_grid`, a metric over one or two axes with
  95 % intervals (drawn by :func:`persuasive.plots.sweep.sweep_figure`).

From Python::

    from persuasive import sweep

    grid = sweep.Grid.from_toml("grid.toml")
    summary = sweep.run(grid, "results/my-sweep", workers=2)   # or scheduler="tcp://..."
    frame = sweep.load("results/my-sweep")                     # one row per run

This package does not import matplotlib, and imports Dask only when a sweep runs. The sweep
against the process pool of ``reproduce`` (``persuasive bench --sweep``) is
:func:`persuasive.bench_sweep.bench_sweep`, above both.
"""

from .grid import Grid
from .metrics import METRICS, MetricGrid, metric_grid
from .records import flatten, unflatten
from .runner import SweepSummary, run
from .store import load, load_failures, read_manifest, summary_columns

__all__ = ["METRICS", "Grid", "MetricGrid", "SweepSummary", "flatten", "load", "load_failures",
           "metric_grid", "read_manifest", "run", "summary_columns", "unflatten"]
