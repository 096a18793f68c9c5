"""The top view of a SUMO episode, drawn from its per-step logs (``persuasive sumo --video``).

:func:`sumo_frames` renders one frame per SUMO step (0.1 s) with an explicit Agg canvas: the
network's lanes (from their shapes in the ``.net.xml``) as grey strips, every vehicle as its
rectangle (SUMO logs the front bumper's centre and the heading in degrees clockwise from
north), the ego red, SUMO's drivers blue and those that ignore foes orange.
"""

from __future__ import annotations

from typing import Iterator, Mapping

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Polygon

from ._common import AV_COLOR, HV_COLOR, _FONT

RECKLESS_COLOR = "#e08a1e"


def _corners(x: float, y: float, angle_deg: float, length: float, width: float) -> np.ndarray:
    """Corners (4, 2) [m] of a vehicle whose front bumper's centre is ``(x, y)``."""
    th = np.radians(angle_deg)
    along = np.array([np.sin(th), np.cos(th)])
    left = np.array([-along[1], along[0]])
    front = np.array([x, y])
    back = front - length * along
    hw = 0.5 * width * left
    return np.array([back - hw, front - hw, front + hw, back + hw])


def _lane_strip(shape: np.ndarray, width: float) -> list[np.ndarray]:
    """One quadrilateral per segment of a lane's centre line."""
    out = []
    for p, q in zip(shape[:-1], shape[1:]):
        d = q - p
        n = np.hypot(*d)
        if n == 0.0:
            continue
        left = np.array([-d[1], d[0]]) / n * 0.5 * width
        out.append(np.array([p - left, q - left, q + left, p + left]))
    return out


def sumo_frames(steps, lanes: Mapping[str, np.ndarray], sizes: Mapping[str, tuple[float, float]],
                title: str, view_m: float = 70.0, lane_width_m: float = 3.2,
                dpi: float = 100.0, size_in: float = 6.0) -> Iterator[np.ndarray]:
    """Frames (RGB ``(h, w, 3)`` uint8) of one episode's per-step log ``steps`` (a DataFrame
    with ``t_s, vehicle, x_m, y_m, angle_deg, reckless``); ``lanes``: lane id to shape
    (n, 2) [m]; ``sizes``: ``(length, width)`` [m] of ``"ego"`` and ``"other"``; a square
    window of half-width ``view_m`` around the origin (the junction)."""
    fig = Figure(figsize=(size_in, size_in), dpi=dpi, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for shape in lanes.values():
        for quad in _lane_strip(np.asarray(shape, float), lane_width_m):
            ax.add_patch(Polygon(quad, closed=True, fc="0.86", ec="none", zorder=1))
    ax.set_xlim(-view_m, view_m)
    ax.set_ylim(-view_m, view_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]", fontsize=_FONT["label"])
    ax.set_ylabel("y [m]", fontsize=_FONT["label"])
    ax.legend(handles=[Patch(fc=AV_COLOR, label="ego (planner)"),
                       Patch(fc=HV_COLOR, label="SUMO driver"),
                       Patch(fc=RECKLESS_COLOR, label="SUMO driver ignoring foes")],
              loc="upper left", fontsize=_FONT["legend"], frameon=False)
    heading = ax.set_title(title, fontsize=_FONT["title"])
    canvas.draw()
    fig.set_layout_engine("none")
    heading.set_text("")  # drawn per frame over the background
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    for t, rows in steps.groupby("t_s", sort=True):
        patches = []
        for r in rows.itertuples(index=False):
            ego = r.vehicle == "ego"
            length, width = sizes["ego" if ego else "other"]
            color = AV_COLOR if ego else (RECKLESS_COLOR if r.reckless else HV_COLOR)
            p = Polygon(_corners(r.x_m, r.y_m, r.angle_deg, length, width), closed=True,
                        fc=color, ec="black", lw=0.4, zorder=3)
            ax.add_patch(p)
            patches.append(p)
        heading.set_text(f"{title}   t = {t:5.1f} s")
        canvas.restore_region(background)
        for p in patches:
            ax.draw_artist(p)
        fig.draw_artist(heading)
        frame = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        for p in patches:
            p.remove()
        yield frame


__all__ = ["sumo_frames"]
