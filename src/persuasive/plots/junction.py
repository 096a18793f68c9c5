"""A run of N vehicles seen from above (``persuasive.many``): the roads, every vehicle's path
driven (a line, the AV's thicker), its footprint at a few times, crashes marked
(:func:`topview_figure`); every vehicle's speed and acceleration (:func:`profile_figure`);
and the run as a video, one frame per step (:func:`video`).

Every function reads the run's tables (``persuasive.tables.Trace``), so it draws a junction's
run (a ``JunctionWorld``, whose roads are drawn too) and a two-vehicle run as their N = 2 case
(``RunRecord.trace()``) alike."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon, Rectangle

from ._common import _COLORS, _new_figure


def _corners(xy: np.ndarray, u: np.ndarray, length: float, width: float) -> np.ndarray:
    n = np.array([-u[1], u[0]])
    hl, hw = 0.5 * length * u, 0.5 * width * n
    return np.array([xy + hl + hw, xy + hl - hw, xy - hl - hw, xy - hl + hw])


def _roads(ax, spec, reach: float) -> None:
    half = spec.half_m
    ax.add_patch(Rectangle((-reach, -half), 2 * reach, 2 * half, color="0.86", zorder=0))
    ax.add_patch(Rectangle((-half, -reach), 2 * half, 2 * reach, color="0.86", zorder=0))
    for c in (-1, 1):  # the stop lines and the centre lines
        ax.plot([c * half, c * half], [-half, half], color="0.6", lw=0.5, zorder=1)
        ax.plot([-half, half], [c * half, c * half], color="0.6", lw=0.5, zorder=1)
    ax.plot([-reach, -half], [0, 0], [half, reach], [0, 0], color="0.99", lw=0.6, ls="--")
    ax.plot([0, 0], [-reach, -half], [0, 0], [half, reach], color="0.99", lw=0.6, ls="--")
    ax.set_xlim(-reach, reach)
    ax.set_ylim(-reach, reach)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _trace(world):
    """The run's tables and, at a junction, its spec (for the roads)."""
    from ..tables import Trace

    return (world, None) if isinstance(world, Trace) else (world.trace(), world.spec)


def _footprint(trace, i: int, k: int) -> np.ndarray | None:
    sk = trace.S[k, i]
    if not np.isfinite(sk):
        return None
    x, y, heading = trace.place(i, np.array([sk]))
    u = np.array([math.cos(heading[0]), math.sin(heading[0])])
    lim = trace.limits[i]
    return _corners(np.array([x[0], y[0]]), u, lim.length_m, lim.width_m)


def _view(ax, trace, spec, view_m: float) -> None:
    """The roads of a junction; otherwise a square around every position of the run."""
    if spec is not None:
        _roads(ax, spec, view_m)
        return
    xs, ys = [], []
    for i in range(trace.n):
        s = trace.S[: trace.k + 1, i]
        x, y, _ = trace.place(i, s[np.isfinite(s)])
        xs.append(x)
        ys.append(y)
    x, y = np.concatenate(xs), np.concatenate(ys)
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    half = 0.5 * max(x.max() - x.min(), y.max() - y.min()) + 5.0
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy - half, cy + half)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _what(trace, spec) -> str:
    return f"junction, {trace.n} vehicles" if spec is not None else f"{trace.n} vehicles"


def topview_figure(world, snapshots: int = 4, view_m: float = 45.0,
                   every_s: float | None = None) -> Figure:
    """The figure of a finished run (a :class:`persuasive.many.world.JunctionWorld` or any
    ``persuasive.tables.Trace``): footprints at ``snapshots + 1`` evenly spaced times, or
    every ``every_s`` seconds."""
    trace, spec = _trace(world)
    fig = _new_figure(6.0, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    _view(ax, trace, spec, view_m)
    n_k = trace.k
    if every_s is None:
        times = np.linspace(0, n_k, snapshots + 1).round().astype(int)
    else:
        times = np.unique(np.arange(0.0, n_k * trace.dt + 1e-9, every_s) / trace.dt
                          ).round().astype(int)
        times = times[times <= n_k]
    colors = [_COLORS["av"]] + [_COLORS["hv"]] * (trace.n - 1)
    for i in range(trace.n):
        s = trace.S[: n_k + 1, i]
        s = s[np.isfinite(s)]
        if not s.size:
            continue
        x, y, _ = trace.place(i, s)
        ax.plot(x, y, color=colors[i], lw=2.0 if i == 0 else 0.8, alpha=0.8,
                zorder=3 if i == 0 else 2)
        for alpha, k in zip(np.linspace(0.25, 0.9, len(times)), times):
            corners = _footprint(trace, i, k)
            if corners is not None:
                ax.add_patch(Polygon(corners, closed=True, color=colors[i],
                                     alpha=float(alpha), lw=0, zorder=4))
    for t, i, j, caused in trace.collisions:
        k = int(round(t / trace.dt))
        for v in (i, j):
            sk = trace.S[max(k - 1, 0), v]
            if np.isfinite(sk):
                x, y, _ = trace.place(v, np.array([sk]))
                ax.plot(x[0], y[0], marker="x", color="k", ms=8, zorder=5)
    shown = ("at " + ", ".join(f"{k * trace.dt:.0f}" for k in times) + " s"
             if len(times) <= 8 else f"every {every_s:g} s")
    ax.set_title(f"{_what(trace, spec)}, seed {trace.seed}: AV (thick) and humans; "
                 f"footprints {shown}", fontsize=7)
    return fig


def profile_figure(world) -> Figure:
    """Every vehicle's speed and acceleration over a finished run (the AV thick and red, the
    humans thin and blue; a line ends where its vehicle leaves the road)."""
    trace, spec = _trace(world)
    fig = _new_figure(7.0, 5.0)
    ax_v, ax_a = fig.subplots(2, 1, sharex=True)
    t = np.arange(trace.k + 1) * trace.dt
    for i in range(trace.n - 1, -1, -1):  # the AV drawn last, on top
        color, lw = (_COLORS["av"], 2.0) if i == 0 else (_COLORS["hv"], 0.8)
        ax_v.plot(t, trace.V[: trace.k + 1, i], color=color, lw=lw, alpha=0.9)
        a = trace.A[: trace.k, i]
        ax_a.step(t[:-1], a, where="post", color=color, lw=lw, alpha=0.9)
    ax_v.set_ylabel("speed [m/s]")
    ax_a.set_ylabel("acceleration [m/s$^2$]")
    ax_a.set_xlabel("t [s]")
    ax_v.set_title(f"{_what(trace, spec)}, seed {trace.seed}: the AV (thick) and the "
                   "humans", fontsize=8)
    return fig


def frames(world, view_m: float = 45.0, dpi: float = 80.0):
    """One RGB frame ``(h, w, 3)`` per state of a finished run (a generator): the roads drawn
    once, the footprints of that state (the AV red, the humans blue, crashed ones grey)."""
    trace, spec = _trace(world)
    fig = _new_figure(5.0, 5.0)
    fig.set_dpi(dpi)
    ax = fig.add_subplot(1, 1, 1)
    _view(ax, trace, spec, view_m)
    colors = [_COLORS["av"]] + [_COLORS["hv"]] * (trace.n - 1)
    for k in range(trace.k + 1):
        patches = []
        for i in range(trace.n):
            corners = _footprint(trace, i, k)
            if corners is not None:
                patches.append(ax.add_patch(Polygon(corners, closed=True, color=colors[i],
                                                    lw=0, zorder=4)))
        ax.set_title(f"seed {trace.seed}, t = {k * trace.dt:4.1f} s", fontsize=8)
        fig.canvas.draw()
        yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        for p in patches:
            p.remove()


def video(world, path: str | Path, fps: int | None = None) -> Path:
    """The run as a video (MP4 or GIF, by extension), one frame per step, at ``fps`` frames
    per second (unset: the run's rate, real time), atomically."""
    from .files import write_frames

    rate = fps if fps is not None else max(1, int(round(1.0 / world.dt)))
    return write_frames(frames(world), path, fps=rate)


def topview(world, path: str | Path) -> Path:
    """Draw :func:`topview_figure` to ``path`` (PNG, PDF or SVG), atomically."""
    from .files import save_figure

    fig = topview_figure(world)
    return save_figure(fig, path, dpi=150.0)


__all__ = ["frames", "profile_figure", "topview", "topview_figure", "video"]
