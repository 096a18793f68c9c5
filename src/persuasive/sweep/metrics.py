"""Metrics of a sweep over one or two of its axes, with 95 % confidence intervals.

A metric is either a proportion of runs (in percent), with a Wilson score interval, or a mean
over runs, with the normal-approximation interval ``mean +- 1.96 s / sqrt(n)`` (``s`` the
sample standard deviation; no interval for a single run). Both are deterministic: no
resampling.

:func:`metric_grid` computes a metric for every value of one axis (``x``) or every pair of
values of two (``x``, ``y``), in the grid's order of values. Runs may be restricted to given
values of other axes (``where``); the axes left over are pooled, and the result says which.
The result is a :class:`MetricGrid`, which :func:`persuasive.plots.sweep.sweep_figure` draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ..config import ConfigError
from .store import load, read_manifest, summary_columns

#: z of a two-sided 95 % interval.
Z95 = 1.959963984540054


@dataclass(frozen=True)
class Metric:
    """A per-run quantity and how to aggregate it."""

    label: str  #: axis label, units included
    kind: str  #: "proportion" (percent of runs, Wilson interval) or "mean" (normal interval)
    columns: tuple[str, ...]  #: dataset columns it reads
    value: Callable[[Any], Any]  #: frame -> per-run values (booleans for a proportion)


#: The metrics, by the name ``--metric`` takes.
METRICS: dict[str, Metric] = {
    "av_first_pct": Metric("AV first at the crossing line [% of runs]", "proportion",
                           ("first_at_line",), lambda f: f["first_at_line"] == 1),
    "hv_first_pct": Metric("HV first at the crossing line [% of runs]", "proportion",
                           ("first_at_line",), lambda f: f["first_at_line"] == 2),
    "same_step_pct": Metric("both at the line in the same step [% of runs]", "proportion",
                            ("first_at_line",), lambda f: f["first_at_line"] == 3),
    "neither_pct": Metric("neither at the crossing line [% of runs]", "proportion",
                          ("first_at_line",), lambda f: f["first_at_line"] == 0),
    "collision_pct": Metric("collisions [% of runs]", "proportion", ("collision",),
                            lambda f: f["collision"].astype(bool)),
    "infeasible_pct": Metric("runs with an infeasible MPC step [% of runs]", "proportion",
                             ("infeasible_steps",), lambda f: f["infeasible_steps"] > 0),
    "min_distance_m": Metric("minimum distance, mean [m]", "mean", ("min_distance_m",),
                             lambda f: f["min_distance_m"]),
    "min_distance_to_line_m": Metric("minimum distance up to the line, mean [m]", "mean",
                                     ("min_distance_to_line_m",),
                                     lambda f: f["min_distance_to_line_m"]),
    "hv_role_changes": Metric("HV role changes per run, mean", "mean", ("hv_role_changes",),
                              lambda f: f["hv_role_changes"]),
    # liveness (docs/method.md §12.8)
    "both_cleared_pct": Metric("both vehicles through [% of runs]", "proportion",
                               ("both_cleared",), lambda f: f["both_cleared"].astype(bool)),
    "av_first_through_pct": Metric("AV first through the conflict point [% of runs]",
                                   "proportion", ("av_first_through",),
                                   lambda f: f["av_first_through"].astype(bool)),
    "deadlock_pct": Metric("standoffs (two vehicles) or deadlocks (a junction) [% of runs]",
                           "proportion", ("deadlock",), lambda f: f["deadlock"].astype(bool)),
    "wait_s": Metric("longer wait of the two, mean [s]", "mean", ("av_wait_s", "hv_wait_s"),
                     lambda f: np.maximum(f["av_wait_s"], f["hv_wait_s"])),
    # what the shield's overrides cost (issue 25 item 6)
    "override_pct": Metric("steps the shield overrode, mean [% of steps]", "mean",
                           ("override_share",), lambda f: 100.0 * f["override_share"]),
    "override_mps2": Metric("change the shield made to the proposal, mean [m/s^2]", "mean",
                            ("override_mps2",), lambda f: f["override_mps2"]),
    # the junction of many vehicles (scenario.kind = "junction", docs/method.md §15.6)
    "av_through_pct": Metric("AV through the junction [% of runs]", "proportion",
                             ("av_through",), lambda f: f["av_through"].astype(bool)),
    "av_caused_collision_pct": Metric("runs with an AV-caused collision [% of runs]",
                                      "proportion", ("av_caused_collisions",),
                                      lambda f: f["av_caused_collisions"] > 0),
    "human_collision_pct": Metric("runs with a collision between humans [% of runs]",
                                  "proportion", ("human_collisions",),
                                  lambda f: f["human_collisions"] > 0),
    "av_caused_deadlock_pct": Metric("runs with a deadlock of the AV's own making [% of runs]",
                                     "proportion", ("av_caused_deadlock",),
                                     lambda f: f["av_caused_deadlock"].astype(bool)),
    "av_inside_stood_pct": Metric("runs in which the AV stood inside the junction [% of runs]",
                                  "proportion", ("av_inside_stood_s",),
                                  lambda f: f["av_inside_stood_s"] > 0),
    "caused_delay_s": Metric("delay the AV caused the humans, mean [s]", "mean",
                             ("caused_delay_s",), lambda f: f["caused_delay_s"]),
    "mean_wait_s": Metric("the humans' waiting time, mean [s]", "mean", ("mean_wait_s",),
                          lambda f: f["mean_wait_s"]),
    "throughput_veh_h": Metric("throughput, mean [vehicles per hour]", "mean",
                               ("throughput_veh_h",), lambda f: f["throughput_veh_h"]),
}


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k / n`` (as fractions); NaNs when ``n = 0``."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    denom = 1.0 + z * z / n
    center = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denom
    return max(0.0, center - half), min(1.0, center + half)


def mean_interval(values: np.ndarray, z: float = Z95) -> tuple[float, float, float]:
    """``(mean, lo, hi)``: the normal-approximation interval; NaN bounds for fewer than 2."""
    n = values.size
    if n == 0:
        return math.nan, math.nan, math.nan
    mean = float(values.mean())
    if n < 2:
        return mean, math.nan, math.nan
    half = z * float(values.std(ddof=1)) / math.sqrt(n)
    return mean, mean - half, mean + half


@dataclass(frozen=True)
class MetricGrid:
    """A metric over one axis (arrays of shape ``(nx,)``) or two (``(ny, nx)``)."""

    metric: str  #: the metric's name (a key of :data:`METRICS`)
    label: str  #: its label, units included
    kind: str  #: "proportion" or "mean"
    interval: str  #: how the 95 % interval is computed (for a caption)
    x: str  #: the axis along x
    x_values: tuple[Any, ...]
    y: str | None  #: the axis along y, or None
    y_values: tuple[Any, ...]
    estimate: np.ndarray  #: percent of runs, or the mean; NaN where no run
    lo: np.ndarray  #: lower bound of the 95 % interval
    hi: np.ndarray  #: upper bound
    n: np.ndarray  #: runs per cell
    where: tuple[tuple[str, Any], ...] = ()  #: fixed values of other axes
    pooled: tuple[str, ...] = ()  #: axes pooled over
    digest: str = ""  #: the sweep's grid digest


def _axis_values(manifest: Mapping[str, Any]) -> dict[str, tuple[Any, ...]]:
    import tomllib

    grid = tomllib.loads(manifest["grid_toml"])
    return {name: tuple(grid["axes"][name]) for name in manifest["axes"]}


def _check_axis(name: str, values: Mapping[str, Any], what: str) -> None:
    if name not in values:
        allowed = ", ".join(values) or "none (the grid has no axes)"
        raise ConfigError(f"{what} {name!r} is not an axis of the sweep; allowed: {allowed}")


def metric_grid(folder: str | Path, metric: str, x: str, y: str | None = None,
                where: Mapping[str, Any] | None = None) -> MetricGrid:
    """``metric`` of the sweep in ``folder`` for each value of ``x`` (and ``y``).

    ``where`` fixes other axes to one of their values. Unknown metrics, axes or values raise
    :class:`ConfigError` with a one-line message naming them.
    """
    if metric not in METRICS:
        raise ConfigError(f"metric {metric!r} is not known; allowed: {', '.join(METRICS)}")
    manifest = read_manifest(folder)
    axes = _axis_values(manifest)
    _check_axis(x, axes, "--x")
    if y is not None:
        _check_axis(y, axes, "--y")
        if y == x:
            raise ConfigError(f"--y {y!r} is the same axis as --x; give two different axes")
    where = dict(where or {})
    for name, value in where.items():
        _check_axis(name, axes, "--where")
        if name in (x, y):
            raise ConfigError(f"--where {name!r} is plotted already (--x or --y)")
        if value not in axes[name]:
            shown = ", ".join(repr(v) for v in axes[name])
            raise ConfigError(f"--where {name} = {value!r} is not a value of the axis; "
                              f"allowed: {shown}")
    spec = METRICS[metric]
    have = set(summary_columns(folder))
    missing = [c for c in spec.columns if c not in have]
    if missing:
        usable = ", ".join(m for m, sp in METRICS.items() if set(sp.columns) <= have)
        raise ConfigError(f"metric {metric!r} reads {', '.join(missing)}, which the runs of this "
                          f"sweep do not have; allowed here: {usable or 'none'}")
    frame = load(folder, columns=list(dict.fromkeys([x, *([y] if y else []), *where,
                                                     *spec.columns])))
    for name, value in where.items():
        frame = frame[frame[name] == value]
    xs = axes[x]
    ys = axes[y] if y is not None else (None,)
    shape = (len(ys), len(xs))
    est, lo, hi = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    n = np.zeros(shape, dtype=np.int64)
    values = np.asarray(spec.value(frame), dtype=float) if len(frame) else np.zeros(0)
    xcol = frame[x].to_numpy() if len(frame) else np.zeros(0)
    ycol = frame[y].to_numpy() if (y is not None and len(frame)) else None
    for i, yv in enumerate(ys):
        for j, xv in enumerate(xs):
            mask = xcol == xv
            if ycol is not None:
                mask &= ycol == yv
            cell = values[mask]
            n[i, j] = cell.size
            if spec.kind == "proportion":
                k = int(cell.sum())
                if cell.size:
                    est[i, j] = 100.0 * k / cell.size
                lo[i, j], hi[i, j] = (100.0 * b for b in wilson(k, cell.size))
            else:
                est[i, j], lo[i, j], hi[i, j] = mean_interval(cell)
    if y is None:
        est, lo, hi, n = est[0], lo[0], hi[0], n[0]
    interval = ("Wilson score" if spec.kind == "proportion"
                else "normal approximation, mean \u00b1 1.96 s/\u221an")
    pooled = tuple(a for a in axes if a not in (x, y) and a not in where)
    return MetricGrid(metric, spec.label, spec.kind, interval, x, xs, y,
                      ys if y is not None else (), est, lo, hi, n,
                      tuple(where.items()), pooled, manifest["grid_digest"])


__all__ = ["METRICS", "Metric", "MetricGrid", "Z95", "mean_interval", "metric_grid", "wilson"]
