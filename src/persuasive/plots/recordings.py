"""A recorded pair seen from above (``persuasive recordings pairs --figure FILE --pair ID``).

:func:`pair_figure` draws one :class:`persuasive.recordings.pairs.Pair` to scale in the
recording's map frame: both vehicles' whole smoothed tracks (thin), the stretch both are
recorded together (thick), their occupancy intervals (where each footprint can touch the
other's path, shaded), the conflict point, a dot per second with the time every two seconds,
and both footprints at the moment the first vehicle passes the conflict point (or at the
pair's first step when neither does). Vehicle 1 red, vehicle 2 blue (in a merge, vehicle 1 is
the merging one).
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon

from ._common import _FONT, AV_COLOR, HV_COLOR, SINGLE_COLUMN_IN, _new_figure, _style

_COLORS = (AV_COLOR, HV_COLOR)


def _footprint(x: float, y: float, heading: float, length: float, width: float) -> np.ndarray:
    """The corners (4, 2) of a rectangle centred at ``(x, y)`` along ``heading`` [rad]."""
    d = np.array([math.cos(heading), math.sin(heading)])
    n = np.array([-d[1], d[0]])
    c = np.array([x, y])
    hl, hw = 0.5 * length * d, 0.5 * width * n
    return np.array([c + hl + hw, c - hl + hw, c - hl - hw, c + hl - hw])


def _direction_at(xs: np.ndarray, ys: np.ndarray, k: int) -> float:
    """The direction of travel [rad] at sample ``k`` of a path (its neighbours' chord)."""
    a, b = max(k - 2, 0), min(k + 2, xs.shape[0] - 1)
    return math.atan2(ys[b] - ys[a], xs[b] - xs[a]) if b > a else 0.0


def pair_figure(pair, tracks) -> Figure:
    """The top view of ``pair`` (:class:`persuasive.recordings.pairs.Pair`), whose tracks are
    rows ``pair.index`` of ``tracks`` (:class:`persuasive.recordings.tracks.Tracks`)."""
    fig = _new_figure(SINGLE_COLUMN_IN * 1.5, SINGLE_COLUMN_IN * 1.5)
    ax = fig.add_subplot()
    t_ref = pair.t_pass_s[0] if pair.first == "1" else (
        pair.t_pass_s[1] if pair.first in ("2", "same time") else float(pair.t[0]))
    k_ref = int(np.argmin(np.abs(pair.t - t_ref)))
    for v, i in enumerate(pair.index):
        color = _COLORS[v]
        rows = tracks.rows(i)
        xs, ys, ts = tracks.x[rows], tracks.y[rows], tracks.t[rows]
        ax.plot(xs, ys, color=color, lw=0.6, alpha=0.5, gid=f"track-{v + 1}")
        ax.plot(pair.x[v], pair.y[v], color=color, lw=1.8, gid=f"pair-{v + 1}")
        s = pair.s[v]
        lo, hi = pair.occupancy[v]
        inside = (s >= lo) & (s <= hi)
        if inside.any():
            ax.plot(np.where(inside, pair.x[v], np.nan), np.where(inside, pair.y[v], np.nan),
                    color=color, lw=6.0, alpha=0.25, solid_capstyle="butt",
                    gid=f"occupancy-{v + 1}")
        whole = np.isclose(np.mod(ts + 1e-6, 1.0), 0.0, atol=1e-3)
        ax.plot(xs[whole], ys[whole], "o", color=color, ms=2.0, gid=f"seconds-{v + 1}")
        for k in np.flatnonzero(np.isclose(np.mod(ts + 1e-6, 2.0), 0.0, atol=1e-3)):
            ax.annotate(f"{ts[k]:.0f}", (xs[k], ys[k]), xytext=(3, 3),
                        textcoords="offset points", fontsize=_FONT["note"], color=color)
        heading = _direction_at(pair.x[v], pair.y[v], k_ref)
        ax.add_patch(Polygon(_footprint(pair.x[v][k_ref], pair.y[v][k_ref], heading,
                                        pair.lengths_m[v], pair.widths_m[v]), closed=True,
                             fc=color, ec="k", lw=0.5, alpha=0.8, zorder=5,
                             gid=f"footprint-{v + 1}"))
    ax.plot(*pair.conflict_xy, marker="x", color="k", ms=7, mew=1.5, zorder=6,
            gid="conflict-point")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]", fontsize=_FONT["label"])
    ax.set_ylabel("y [m]", fontsize=_FONT["label"])
    _style(ax)
    def secs(x: float) -> str:
        return "-" if math.isnan(x) else f"{x:.2f} s"

    # both PETs, each named (persuasive.recordings.pairs): at the conflict area with the
    # lengths, and on the occupancy intervals
    ax.set_title(f"{pair.recording}, pair {pair.pair}: {pair.kind} at {pair.angle_deg:.0f} deg\n"
                 f"first: vehicle {pair.first}, PET at the area {secs(pair.pet_area_s)}, on the intervals "
                 f"{secs(pair.pet_s)}; footprints at t = "
                 f"{pair.t[k_ref]:.1f} s", fontsize=_FONT["title"])
    ax.legend(handles=[
        Line2D([], [], color=_COLORS[0], lw=1.8,
               label=f"1: track {pair.tracks[0]} ({pair.classes[0]})"),
        Line2D([], [], color=_COLORS[1], lw=1.8,
               label=f"2: track {pair.tracks[1]} ({pair.classes[1]})"),
        Line2D([], [], color="k", marker="x", lw=0, label="conflict point")],
        fontsize=_FONT["legend"], frameon=False, loc="best")
    return fig


__all__ = ["pair_figure"]
