"""Single top-view frames of a running world: :class:`persuasive.envs.conflict.ConflictEnv`
(``render_mode="rgb_array"``) draws with them.

The scene is drawn as the package's top view (:func:`persuasive.plots.topview.draw_scene`,
the vehicles' footprints along their paths, HV blue, AV red) on an explicit Agg canvas; the
window is fixed for the whole episode (both starts to a vehicle length past each one's
clearing position), so that consecutive frames line up. Imported only when a frame is drawn.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ._common import _COLORS, _FONT, _style
from .topview import _vehicle_patch, _vehicle_xy, draw_scene


def new_frame_figure(size_in: float, dpi: float) -> Figure:
    """A square figure of ``size_in`` inches at ``dpi`` with its Agg canvas."""
    fig = Figure(figsize=(size_in, size_in), dpi=dpi)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.11, top=0.92)
    return fig


def frame_limits(world) -> tuple[float, float]:
    """One square window ``(lo, hi)`` [m] for x and y: both vehicles from their start to a
    vehicle length past their clearing position, and the conflict point."""
    scene = world.scenario
    pts = [np.zeros((1, 2))]
    for who, j in (("av", 0), ("hv", 2)):
        path = getattr(scene, who)
        s0 = float(world.states[0, j])
        end = max(s0, path.clear_s) + path.vehicle.length_m
        pts.append(path.polyline(s0, end, 0.5))
    pts = np.concatenate(pts)
    margin = max(scene.av.vehicle.length_m, scene.hv.vehicle.length_m) + 2.0
    return float(pts.min()) - margin, float(pts.max()) + margin


def render_frame(fig: Figure, world, controlled: str) -> np.ndarray:
    """Draw the world's current state into ``fig``; returns RGB ``(H, W, 3)`` uint8."""
    k = world.k
    run = SimpleNamespace(states=world.states[:k + 1], scenario=world.scenario,
                          config=world.config)
    fig.clear()
    ax = fig.add_subplot()
    draw_scene(ax, run, frame_limits(world))
    for who in ("hv", "av"):
        color = _COLORS[who]
        x, y = _vehicle_xy(run, who, np.arange(k + 1))
        ax.plot(x, y, color=color, lw=1.0, zorder=2)
        ax.add_patch(_vehicle_patch(run, who, k, fc=color, ec="black", lw=0.5, zorder=3,
                                    label=f"{who.upper()}" + (" (agent)" if who == controlled
                                                              else "")))
    ax.legend(loc="upper left", fontsize=_FONT["legend"], frameon=False)
    ax.set_title(f"{world.config.scenario.kind}, t = {k * world.dt:.1f} s",
                 fontsize=_FONT["title"])
    ax.set_xlabel("x [m]", fontsize=_FONT["label"])
    ax.set_ylabel("y [m]", fontsize=_FONT["label"])
    _style(ax, grid=False)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
