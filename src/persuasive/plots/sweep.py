"""A metric of a parameter sweep over one axis (a line) or two (a heatmap, or one line per
value of the second axis), with 95 % intervals.

:func:`sweep_figure` draws a :class:`persuasive.sweep.metrics.MetricGrid` (computed by
:func:`persuasive.sweep.metrics.metric_grid` from a sweep folder): with one axis, the metric
against the axis values with its 95 % interval as error bars and a band; with two, a heatmap
whose cells show the value and the interval ``[lo, hi]``. Proportions use Wilson score
intervals, means the normal approximation (the figure says which). Numeric axes are drawn to
scale on a line plot; other axes (strings, booleans) as evenly spaced categories.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..sweep.metrics import MetricGrid

_COLOR = "#d62728"
_FONT = {"label": 8.0, "tick": 7.0, "title": 8.5, "note": 6.5, "cell": 6.0}


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def _fmt(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _fmt_metric(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{value:.1f}" if abs(value) >= 10 else \
        f"{value:.2f}"


def _note(data: MetricGrid) -> str:
    parts = []
    if data.where:
        parts.append(", ".join(f"{k} = {_fmt(v)}" for k, v in data.where))
    if data.pooled:
        parts.append("pooled over " + ", ".join(data.pooled))
    counts = np.unique(data.n)
    parts.append(f"n = {counts[0]} runs per point" if counts.size == 1
                 else f"n = {counts.min()}..{counts.max()} runs per point")
    parts.append(f"95 % interval: {data.interval}")
    if data.digest:
        parts.append(f"sweep {data.digest}")
    return "; ".join(parts)


def _new_figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _x_axis(ax, data: MetricGrid) -> tuple[np.ndarray, np.ndarray]:
    """The x positions in drawing order and that order: a numeric axis to scale, sorted;
    another as evenly spaced categories in the grid's order (ticks named)."""
    xs = list(data.x_values)
    if _numeric(xs):
        pos = np.asarray(xs, dtype=float)
        order = np.argsort(pos, kind="stable")
    else:
        pos = np.arange(len(xs), dtype=float)
        order = np.arange(len(xs))
        ax.set_xticks(pos, [_fmt(v) for v in xs])
    return pos[order], order


def _line(data: MetricGrid) -> Figure:
    fig = _new_figure(4.5, 3.2)
    ax = fig.subplots()
    p, order = _x_axis(ax, data)
    est, lo, hi = data.estimate[order], data.lo[order], data.hi[order]
    ax.fill_between(p, lo, hi, color=_COLOR, alpha=0.15, linewidth=0, gid="sweep-interval")
    yerr = np.vstack([est - lo, hi - est])
    ax.errorbar(p, est, yerr=np.where(np.isnan(yerr), 0.0, yerr), color=_COLOR, marker="o",
                ms=3.5, lw=1.2, capsize=2.5, gid="sweep-metric")
    ax.set_xlabel(data.x, fontsize=_FONT["label"])
    ax.set_ylabel(data.label, fontsize=_FONT["label"])
    if data.kind == "proportion":
        top = np.nanmax(hi) if np.any(np.isfinite(hi)) else 100.0
        ax.set_ylim(-2.0, min(102.0, max(5.0, top * 1.1 + 1.0)))
    ax.tick_params(labelsize=_FONT["tick"])
    ax.grid(True, linewidth=0.4, alpha=0.35)
    ax.set_title(data.metric, fontsize=_FONT["title"])
    fig.text(0.5, 0.0, _note(data), ha="center", va="bottom", fontsize=_FONT["note"],
             wrap=True)
    fig.get_layout_engine().set(rect=(0, 0.06, 1, 0.94))
    return fig


#: The colours of :func:`_series` (one line per value of the second axis).
_SERIES_COLORS = ("#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
                  "#7f7f7f", "#bcbd22", "#17becf")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")


def _series(data: MetricGrid) -> Figure:
    """Two axes drawn as lines: one per value of ``data.y`` against ``data.x``, each with its
    95 % interval as error bars (no band: they would hide one another)."""
    fig = _new_figure(5.2, 3.4)
    ax = fig.subplots()
    p, order = _x_axis(ax, data)
    for i, value in enumerate(data.y_values):
        est, lo, hi = data.estimate[i, order], data.lo[i, order], data.hi[i, order]
        yerr = np.vstack([est - lo, hi - est])
        ax.errorbar(p, est, yerr=np.where(np.isnan(yerr), 0.0, yerr),
                    color=_SERIES_COLORS[i % len(_SERIES_COLORS)],
                    marker=_MARKERS[i % len(_MARKERS)], ms=3.5, lw=1.1, capsize=2.0,
                    label=_fmt(value), gid=f"sweep-series-{i}")
    ax.set_xlabel(data.x, fontsize=_FONT["label"])
    ax.set_ylabel(data.label, fontsize=_FONT["label"])
    if data.kind == "proportion":
        top = np.nanmax(data.hi) if np.any(np.isfinite(data.hi)) else 100.0
        ax.set_ylim(-2.0, min(102.0, max(5.0, top * 1.1 + 1.0)))
    ax.tick_params(labelsize=_FONT["tick"])
    ax.grid(True, linewidth=0.4, alpha=0.35)
    ax.legend(title=data.y, fontsize=_FONT["note"], title_fontsize=_FONT["note"],
              loc="best", frameon=False)
    ax.set_title(data.metric, fontsize=_FONT["title"])
    fig.text(0.5, 0.0, _note(data), ha="center", va="bottom", fontsize=_FONT["note"],
             wrap=True)
    fig.get_layout_engine().set(rect=(0, 0.06, 1, 0.94))
    return fig


def _heatmap(data: MetricGrid) -> Figure:
    nx, ny = len(data.x_values), len(data.y_values)
    fig = _new_figure(max(4.0, 1.2 + 0.75 * nx), max(3.0, 1.6 + 0.45 * ny))
    ax = fig.subplots()
    est = np.ma.masked_invalid(data.estimate)
    image = ax.imshow(est, origin="lower", aspect="auto", cmap="viridis",
                      interpolation="nearest", gid="sweep-heatmap")
    bar = fig.colorbar(image, ax=ax, shrink=0.9)
    bar.set_label(data.label, fontsize=_FONT["label"])
    bar.ax.tick_params(labelsize=_FONT["tick"])
    lo_c, hi_c = image.get_clim()
    for i in range(ny):
        for j in range(nx):
            value = data.estimate[i, j]
            text = _fmt_metric(value)
            if not math.isnan(data.lo[i, j]):
                text += f"\n[{_fmt_metric(data.lo[i, j])}, {_fmt_metric(data.hi[i, j])}]"
            frac = 0.5 if hi_c == lo_c or math.isnan(value) else (value - lo_c) / (hi_c - lo_c)
            ax.text(j, i, text, ha="center", va="center", fontsize=_FONT["cell"],
                    color="black" if frac > 0.6 else "white", gid=f"sweep-cell-{i}-{j}")
    ax.set_xticks(np.arange(nx), [_fmt(v) for v in data.x_values])
    ax.set_yticks(np.arange(ny), [_fmt(v) for v in data.y_values])
    ax.set_xlabel(data.x, fontsize=_FONT["label"])
    ax.set_ylabel(data.y, fontsize=_FONT["label"])
    ax.tick_params(labelsize=_FONT["tick"], length=2.5)
    ax.set_title(f"{data.metric} (cells: value [95 % interval])", fontsize=_FONT["title"])
    fig.text(0.5, 0.0, _note(data), ha="center", va="bottom", fontsize=_FONT["note"],
             wrap=True)
    fig.get_layout_engine().set(rect=(0, 0.06, 1, 0.94))
    return fig


def sweep_figure(data: MetricGrid, series: bool = False) -> Figure:
    """The metric of ``data`` as a line plot (one axis) or a heatmap (two axes), or with two
    axes and ``series``, one line per value of the second (``data.y``).

    Parameters
    ----------
    data : persuasive.sweep.metrics.MetricGrid
        From :func:`persuasive.sweep.metrics.metric_grid`.
    series : bool
        Draw the second axis as lines (e.g. one per AV kind) instead of a heatmap.

    Returns
    -------
    matplotlib.figure.Figure
        Built with the object API (an Agg canvas, no pyplot); save it with
        :func:`persuasive.plots.files.save_figure`.
    """
    if not isinstance(data, MetricGrid):
        raise TypeError(f"expected a MetricGrid, got {type(data).__name__}")
    if data.y is None:
        return _line(data)
    return _series(data) if series else _heatmap(data)


__all__ = ["sweep_figure"]
