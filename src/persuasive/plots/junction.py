"""A run at the four-way junction seen from above (``persuasive.many``): the roads, every
vehicle's path driven (a line, the AV's thicker), its footprint at a few times, crashes
marked (:func:`topview_figure`); and the run as a video, one frame per step
(:func:`video`)."""

from __future__ import annotations

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


def _footprint(world, i: int, k: int) -> np.ndarray | None:
    sk = world.S[k, i]
    if not np.isfinite(sk):
        return None
    p = world.routes[i].line.at(np.array([sk - 0.25, sk, sk + 0.25]))
    d = p[2] - p[0]
    u = d / max(float(np.hypot(*d)), 1e-12)
    lim = world.limits[i]
    return _corners(p[1], u, lim.length_m, lim.width_m)


def topview_figure(world, snapshots: int = 4, view_m: float = 45.0,
                   every_s: float | None = None) -> Figure:
    """The figure of a finished :class:`persuasive.many.world.JunctionWorld` run: footprints
    at ``snapshots + 1`` evenly spaced times, or every ``every_s`` seconds."""
    fig = _new_figure(6.0, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    reach = view_m
    _roads(ax, world.spec, reach)
    n_k = world.k
    if every_s is None:
        times = np.linspace(0, n_k, snapshots + 1).round().astype(int)
    else:
        times = np.unique(np.arange(0.0, n_k * world.dt + 1e-9, every_s) / world.dt
                          ).round().astype(int)
        times = times[times <= n_k]
    colors = [_COLORS["av"]] + [_COLORS["hv"]] * (world.n - 1)
    for i, r in enumerate(world.routes):
        s = world.S[: n_k + 1, i]
        s = s[np.isfinite(s)]
        if not s.size:
            continue
        xy = r.line.at(s)
        ax.plot(xy[:, 0], xy[:, 1], color=colors[i], lw=2.0 if i == 0 else 0.8, alpha=0.8,
                zorder=3 if i == 0 else 2)
        for alpha, k in zip(np.linspace(0.25, 0.9, len(times)), times):
            corners = _footprint(world, i, k)
            if corners is not None:
                ax.add_patch(Polygon(corners, closed=True, color=colors[i],
                                     alpha=float(alpha), lw=0, zorder=4))
    for t, i, j, caused in world.collisions:
        k = int(round(t / world.dt))
        for v in (i, j):
            sk = world.S[max(k - 1, 0), v]
            if np.isfinite(sk):
                x, y = world.routes[v].line.at(np.array([sk]))[0]
                ax.plot(x, y, marker="x", color="k", ms=8, zorder=5)
    shown = ("at " + ", ".join(f"{k * world.dt:.0f}" for k in times) + " s"
             if len(times) <= 8 else f"every {every_s:g} s")
    ax.set_title(f"junction, {world.n} vehicles, seed {world.seed}: AV (thick) and humans; "
                 f"footprints {shown}", fontsize=7)
    return fig


def profile_figure(world) -> Figure:
    """Every vehicle's speed and acceleration over a finished run (the AV thick and red, the
    humans thin and blue; a line ends where its vehicle leaves the road)."""
    fig = _new_figure(7.0, 5.0)
    ax_v, ax_a = fig.subplots(2, 1, sharex=True)
    t = np.arange(world.k + 1) * world.dt
    for i in range(world.n - 1, -1, -1):  # the AV drawn last, on top
        color, lw = (_COLORS["av"], 2.0) if i == 0 else (_COLORS["hv"], 0.8)
        ax_v.plot(t, world.V[: world.k + 1, i], color=color, lw=lw, alpha=0.9)
        a = world.A[: world.k, i]
        ax_a.step(t[:-1], a, where="post", color=color, lw=lw, alpha=0.9)
    ax_v.set_ylabel("speed [m/s]")
    ax_a.set_ylabel("acceleration [m/s$^2$]")
    ax_a.set_xlabel("t [s]")
    ax_v.set_title(f"junction, {world.n} vehicles, seed {world.seed}: the AV (thick) and the "
                   "humans", fontsize=8)
    return fig


def frames(world, view_m: float = 45.0, dpi: float = 80.0):
    """One RGB frame ``(h, w, 3)`` per state of a finished run (a generator): the roads drawn
    once, the footprints of that state (the AV red, the humans blue, crashed ones grey)."""
    fig = _new_figure(5.0, 5.0)
    fig.set_dpi(dpi)
    ax = fig.add_subplot(1, 1, 1)
    _roads(ax, world.spec, view_m)
    colors = [_COLORS["av"]] + [_COLORS["hv"]] * (world.n - 1)
    for k in range(world.k + 1):
        patches = []
        for i in range(world.n):
            corners = _footprint(world, i, k)
            if corners is not None:
                patches.append(ax.add_patch(Polygon(corners, closed=True, color=colors[i],
                                                    lw=0, zorder=4)))
        ax.set_title(f"seed {world.seed}, t = {k * world.dt:4.1f} s", fontsize=8)
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
