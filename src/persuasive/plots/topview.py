"""The paper's Fig. 3: the intersection seen from above, with snapshots of both vehicles.

:func:`topview_figure` draws the two cases of the paper side by side, :func:`topview_single`
one run of any configuration; :func:`draw_intersection` draws the scene (also the animation's
background) and :func:`snapshot_indices` picks the snapshot states.

The scenario geometry comes from the run's scenario (``persuasive.scenarios``): each vehicle's
path gives its centre ``xy(s)`` and direction, so every scenario is drawn to scale:
:func:`draw_intersection` (roads along the paths, crossing and yield lines, safety circle),
:func:`_vehicle_xy`, :func:`_heading`, :func:`_corners` and :func:`_vehicle_patch` (the
footprint, oriented along the path). The snapshot time labels are placed from these and
from the lines drawn (:func:`_draw_time_labels`).
"""

from __future__ import annotations

from numbers import Real
from typing import Any, NamedTuple, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backend_bases import RendererBase
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon

from ..config import ConfigError
from ..simulation import RunRecord
from ._common import (_COLORS, _FONT, DOUBLE_COLUMN_IN, SINGLE_COLUMN_IN, _check_runs, _dt,
                      _new_figure, _style, _subtitle, _titles, _vehicle_handles)

_ROAD_COLOR = "0.86"
_OTHER = {"av": "hv", "hv": "av"}

_Box = tuple[float, float, float, float]  # x0, y0, x1, y1 [m]


# -- scenario geometry --------------------------------------------------------------------------


def _scenario(run: RunRecord):
    """The run's scenario (rebuilt from its configuration when the record has none)."""
    scene = getattr(run, "scenario", None)
    if scene is None:
        from ..scenarios import build_scenario

        scene = build_scenario(run.config)
    return scene


def _vehicle_xy(run: RunRecord, who: str, k: np.ndarray | int) -> tuple[Any, Any]:
    """Centre ``(x, y)`` [m] of ``who`` at state index ``k``, on its path."""
    s = run.states[k, 0 if who == "av" else 2]
    x, y = getattr(_scenario(run), who).xy(s)
    return (x, y) if np.ndim(s) else (float(x), float(y))


def _heading(run: RunRecord, who: str, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction of travel of ``who`` at state index ``k`` and its left normal, in (x, y)."""
    ux, uy = getattr(_scenario(run), who).direction(run.states[k, 0 if who == "av" else 2])
    along = np.array([float(ux), float(uy)])
    return along, np.array([-along[1], along[0]])


def _size(run: RunRecord, who: str) -> tuple[float, float]:
    """``(length, width)`` [m] of ``who``."""
    veh = getattr(_scenario(run), who).vehicle
    return veh.length_m, veh.width_m


def _corners(run: RunRecord, who: str, k: int) -> np.ndarray:
    """The four corners ``(4, 2)`` [m] of ``who``'s footprint at state index ``k``."""
    centre = np.array(_vehicle_xy(run, who, k), dtype=float)
    along, left = _heading(run, who, k)
    length, width = _size(run, who)
    a, b = along * length / 2, left * width / 2
    return np.array([centre - a - b, centre + a - b, centre + a + b, centre - a + b])


def _footprint(run: RunRecord, who: str, k: int = 0) -> tuple[float, float]:
    """Extent ``(along x, along y)`` [m] of the box around ``who``'s footprint at ``k``."""
    c = _corners(run, who, k)
    return float(np.ptp(c[:, 0])), float(np.ptp(c[:, 1]))


def _vehicle_patch(run: RunRecord, who: str, k: int, **kwargs: Any) -> Polygon:
    """``who``'s footprint at state index ``k`` (oriented along its path); ``kwargs`` style
    it."""
    return Polygon(_corners(run, who, k), closed=True, **kwargs)


def _path_points(run: RunRecord, who: str, spacing_m: float = 0.2) -> np.ndarray:
    """Points along ``who``'s centre path over the run, at most ``spacing_m`` apart: ``(n, 2)``
    [m]."""
    s = run.states[:, 0 if who == "av" else 2]
    lo, hi = float(s.min()), float(s.max())
    if hi == lo:
        return np.array([_vehicle_xy(run, who, 0)], dtype=float)
    return getattr(_scenario(run), who).polyline(lo, hi, spacing_m)


def _view_limits(runs: Sequence[RunRecord]) -> tuple[float, float]:
    """One square window (same range for x and y) holding every position of every run and
    the conflict point."""
    pts = [np.zeros((1, 2))]
    for r in runs:
        for who in ("av", "hv"):
            x, y = _vehicle_xy(r, who, np.arange(r.states.shape[0]))
            pts.append(np.column_stack([x, y]))
    pts = np.concatenate(pts)
    margin = max(max(_size(r, "av")[0], _size(r, "hv")[0]) for r in runs) + 2.0
    return float(pts.min()) - margin, float(pts.max()) + margin


def _across(path, s: float, half: float) -> tuple[list[float], list[float]]:
    """A segment across the road of ``path`` at ``s``, ``half`` to each side [m]."""
    x, y = path.xy(s)
    ux, uy = path.direction(s)
    nx, ny = -float(uy), float(ux)
    return [float(x) - half * nx, float(x) + half * nx], [float(y) - half * ny, float(y) + half * ny]


def draw_intersection(ax: Axes, run: RunRecord, limits: tuple[float, float]) -> None:
    """The scene to scale: both roads along their paths, the lines and the safety circle.

    Each road is ``lane_width_m`` wide and centred on its vehicle's path; each vehicle's
    crossing line (whose first arrival decides who went first) is drawn across its road, and
    its yield line (where its stop trajectory stops) dashed where it differs; the dotted circle
    of radius ``min_dist_m`` around the conflict point is the safe-set boundary for the other
    vehicle's centre when one vehicle is at the conflict point. Works for every scenario
    (``persuasive.scenarios``): the paths are drawn from their geometry.
    """
    scene = _scenario(run)
    lo, hi = limits
    half = scene.lane_width_m / 2
    reach = 2.0 * max(abs(lo), abs(hi)) + 10.0
    for who in ("av", "hv"):
        path = getattr(scene, who)
        pts = path.polyline(-reach, reach, 0.25)
        ux, uy = path.direction(np.linspace(-reach, reach, len(pts)))
        normal = np.column_stack([-uy, ux])
        strip = np.concatenate([pts + half * normal, (pts - half * normal)[::-1]])
        ax.add_patch(Polygon(strip, closed=True, color=_ROAD_COLOR, lw=0, zorder=0,
                             gid=f"road-{who}"))
    for who in ("av", "hv"):
        path = getattr(scene, who)
        xs, ys = _across(path, path.first_s, half)
        ax.plot(xs, ys, color="0.15", lw=1.4, solid_capstyle="butt", zorder=1,
                gid=f"{who}-crossing-line")
        if np.isfinite(path.yield_s) and path.yield_s != path.first_s:
            xs, ys = _across(path, path.yield_s, half)
            ax.plot(xs, ys, color="0.15", lw=0.9, ls="--", zorder=1, gid=f"{who}-yield-line")
    cx, cy = scene.av.xy(0.0)
    ax.add_patch(Circle((float(cx), float(cy)), scene.min_dist_m, fill=False, ls=":", lw=0.9,
                        ec="0.25", zorder=1, gid="safety-circle"))
    ax.plot([float(cx)], [float(cy)], marker="+", color="0.25", ms=5, mew=0.8, zorder=1,
            gid="conflict-point")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")


#: :func:`draw_intersection` draws any scenario; this is its general name.
draw_scene = draw_intersection


def _scene_handles(run: RunRecord) -> list[Any]:
    """Legend entries of what :func:`draw_intersection` draws: lines, safety circle."""
    scene = _scenario(run)
    handles = [Line2D([], [], color="0.15", lw=1.4, label="crossing line")]
    if any(np.isfinite(p.yield_s) and p.yield_s != p.first_s for p in (scene.av, scene.hv)):
        handles.append(Line2D([], [], color="0.15", lw=0.9, ls="--", label="yield line"))
    handles.append(Line2D([], [], color="0.25", lw=0.9, ls=":",
                          label=f"safe distance {scene.min_dist_m:g} m"))
    return handles


# -- snapshots ----------------------------------------------------------------------------------


def snapshot_indices(run: RunRecord, every_s: float) -> np.ndarray:
    """State indices ``0, m, 2m, ...`` with ``m = round(every_s / dt)`` (at least 1)."""
    if isinstance(every_s, bool) or not isinstance(every_s, Real) or not np.isfinite(every_s) \
            or every_s <= 0:
        raise ConfigError(f"every = {every_s!r} is out of range; allowed: > 0 seconds")
    m = max(1, int(round(every_s / _dt(run))))
    return np.arange(0, run.states.shape[0], m)


def _draw_snapshots(ax: Axes, run: RunRecord, idx: np.ndarray) -> list[_Box]:
    """Both vehicles' paths and footprints at the state indices ``idx``; returns the boxes."""
    alphas = np.linspace(0.2, 0.75, idx.size) if idx.size > 1 else np.array([0.75])
    boxes = []
    for who in ("hv", "av"):
        color = _COLORS[who]
        x, y = _vehicle_xy(run, who, np.arange(run.states.shape[0]))
        ax.plot(x, y, color=color, lw=1.0, zorder=2, gid=f"{who}-path")
        for k, a in zip(idx, alphas):
            # Opaque outlines keep overlapping snapshots of a slow vehicle apart.
            patch = _vehicle_patch(run, who, int(k), fc=to_rgba(color, a), ec=color, lw=0.7,
                                   zorder=3, gid=f"{who}-snapshot")
            ax.add_patch(patch)
            c = patch.get_xy()
            boxes.append((float(c[:, 0].min()), float(c[:, 1].min()), float(c[:, 0].max()),
                           float(c[:, 1].max())))
    return boxes


# -- time labels --------------------------------------------------------------------------------

#: Clearance kept between a label and a footprint or the axes' frame [m].
_LABEL_PAD_M = 0.15
#: Clearance kept between a label and a drawn line, beyond the line's half width [m].
_LINE_PAD_M = 0.4
#: Clearance kept between two labels, as a fraction of the label's height.
_LABEL_GAP = 0.35
#: Step of the shifts along the road that move a label clear of an obstacle [m].
_SHIFT_STEP_M = 0.25
#: Spacing of the points that stand for the drawn lines [m]; below twice ``_LINE_PAD_M``, so
#: that a line crossing a label always has a point within the clearance.
_LINE_STEP_M = 0.2
#: Lines of :func:`draw_intersection` and :func:`_draw_snapshots` a label must not touch.
_LINE_GIDS = ("av-path", "hv-path", "av-crossing-line", "hv-crossing-line", "av-yield-line",
              "hv-yield-line", "conflict-point")
#: Half the size of the conflict point's marker, as an obstacle [m].
_MARKER_M = 0.4


def _overlap(a: _Box, b: _Box) -> float:
    """Area shared by two boxes [m^2]."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _grow(box: _Box, pad: float) -> _Box:
    return box[0] - pad, box[1] - pad, box[2] + pad, box[3] + pad


def _distance(box: _Box, points: np.ndarray) -> float:
    """Smallest distance from the points ``(n, 2)`` to the box [m]; 0 for a point inside."""
    if len(points) == 0:
        return np.inf
    dx = np.maximum.reduce([box[0] - points[:, 0], np.zeros(len(points)), points[:, 0] - box[2]])
    dy = np.maximum.reduce([box[1] - points[:, 1], np.zeros(len(points)), points[:, 1] - box[3]])
    return float(np.min(np.hypot(dx, dy)))


def _line_points(ax: Axes) -> tuple[np.ndarray, float]:
    """Points ``(n, 2)`` [m] along every line a label must keep clear of (the vehicles' paths,
    the crossing and yield lines, the conflict point), at most ``_LINE_STEP_M`` apart, and the
    largest half width of those lines as drawn [m]."""
    (x0, x1) = ax.get_xlim()
    m_per_pt = (x1 - x0) / (ax.get_window_extent().width * 72.0 / ax.figure.dpi)
    out = [np.zeros((0, 2))]
    half_width = 0.0
    for line in ax.get_lines():
        if line.get_gid() not in _LINE_GIDS:
            continue
        half_width = max(half_width, line.get_linewidth() / 2 * m_per_pt)
        xy = np.asarray(line.get_xydata(), dtype=float)
        if line.get_gid() == "conflict-point":  # a marker: its extent
            out.append(xy + np.array([[dx, dy] for dx in (-_MARKER_M, 0.0, _MARKER_M)
                                      for dy in (-_MARKER_M, 0.0, _MARKER_M)]))
            continue
        for a, b in zip(xy[:-1], xy[1:]):
            n = max(1, int(np.ceil(np.hypot(*(b - a)) / _LINE_STEP_M)))
            out.append(a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None])
        out.append(xy)
    return np.concatenate(out), half_width


class _Scene(NamedTuple):
    """What a label must keep clear of, in one panel."""

    limits: tuple[float, float, float, float]  # x0, y0, x1, y1 of the axes [m]
    footprints: list[_Box]  # every footprint drawn [m]
    lines: np.ndarray  # points along every line drawn, (n, 2) [m]
    line_pad: float  # clearance from those points: _LINE_PAD_M and the lines' half width [m]
    paths: dict[str, np.ndarray]  # each vehicle's centre path, (n, 2) [m]
    circle: tuple[float, float, float]  # the safety circle: centre x, y and radius [m]
    labels: list[_Box]  # the labels placed so far [m]
    placed: dict[str, dict[int, float]]  # per vehicle: snapshot index -> label position [m]


class _Candidate(NamedTuple):
    cost: tuple[bool, float]  # crosses the safety circle's outline; the shift [m]
    box: _Box
    along: float  # the label's position along the vehicle's path [m]


def _label_box(run: RunRecord, who: str, k: int, size: tuple[float, float], side: int,
               shift: float) -> tuple[_Box, float]:
    """The box [m] of ``who``'s label for snapshot ``k`` beside its road, on ``side`` (+1 left,
    -1 right of the direction of travel), shifted ``shift`` along the road, and its position
    along the path [m]."""
    veh = run.config.vehicle
    centre = np.array(_vehicle_xy(run, who, k), dtype=float)
    along, left = _heading(run, who, k)
    w, h = size
    half_across = abs(left[0]) * w / 2 + abs(left[1]) * h / 2
    # Just outside the road, clear of the crossing lines drawn across it.
    gap = max(veh.width_m, veh.lane_width_m) / 2 + 0.3 + half_across
    cx, cy = centre + side * gap * left + shift * along
    s = float(run.states[k, 0 if who == "av" else 2])
    return (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2), s + shift


def _crosses_circle(box: _Box, circle: tuple[float, float, float]) -> bool:
    """Whether the circle's outline passes through the box."""
    cx, cy, r = circle
    near = np.hypot(max(box[0] - cx, 0.0, cx - box[2]), max(box[1] - cy, 0.0, cy - box[3]))
    far = max(np.hypot(x - cx, y - cy) for x in (box[0], box[2]) for y in (box[1], box[3]))
    return near <= r <= far


def _preferred_side(run: RunRecord, who: str, idx: np.ndarray, sizes: list, scene: _Scene) -> int:
    """The side of its road where all of ``who``'s labels go (so that they read in order):
    the one with more snapshots whose label fits there unshifted; then the one farther on
    average from the other vehicle's path; then the one away from where the other vehicle
    comes from."""
    other = scene.paths[_OTHER[who]]
    score = {}
    for side in (1, -1):
        boxes = [_label_box(run, who, int(k), size, side, 0.0)[0] for k, size in zip(idx, sizes)]
        fits = sum(_clear(box, scene) for box in boxes)
        far = float(np.mean([min(_distance(box, other), 10.0) for box in boxes]))
        score[side] = (fits, far, _distance(boxes[0], other[:1]))
    return max((1, -1), key=lambda side: score[side])


def _clear(box: _Box, scene: _Scene) -> bool:
    """Inside the axes and clear of every footprint and drawn line (the labels aside)."""
    x0, y0, x1, y1 = _grow(scene.limits, -_LABEL_PAD_M)
    if box[0] < x0 or box[1] < y0 or box[2] > x1 or box[3] > y1:
        return False
    padded = _grow(box, _LABEL_PAD_M)
    if any(_overlap(padded, f) > 0 for f in scene.footprints):
        return False
    return _distance(box, scene.lines) >= scene.line_pad


def _candidates(run: RunRecord, who: str, i: int, k: int, size: tuple[float, float],
                side: int, scene: _Scene, max_shift_m: float) -> list[_Candidate]:
    """Places for the time label of ``who``'s snapshot ``k`` (the ``i``-th), on ``side``.

    The label sits beside the road, possibly shifted along it by up to ``max_shift_m``. A place
    must be inside the axes, clear of every footprint and drawn line by ``_LABEL_PAD_M``,
    clear of every placed label by ``_LABEL_GAP`` of its height, and keep the vehicle's labels
    in time order along its path. Costs, compared in order: crossing the safety circle's
    outline; the shift.
    """
    n_steps = int(max_shift_m / _SHIFT_STEP_M)
    shifts = _SHIFT_STEP_M * np.r_[0, np.repeat(np.arange(1, n_steps + 1), 2)
                                   * np.tile([1, -1], n_steps)]
    placed = scene.placed[who]
    before = max((a for j, a in placed.items() if j < i), default=-np.inf)
    after = min((a for j, a in placed.items() if j > i), default=np.inf)
    found = []
    for shift in shifts:
        box, along = _label_box(run, who, k, size, side, float(shift))
        if not before < along < after or not _clear(box, scene):
            continue
        spaced = _grow(box, _LABEL_GAP * size[1])
        if any(_overlap(spaced, b) > 0 for b in scene.labels):
            continue
        found.append(_Candidate((_crosses_circle(box, scene.circle), abs(float(shift))), box,
                                along))
    return found


def _label_size(ax: Axes, text: Any, renderer: RendererBase) -> tuple[float, float]:
    """Width and height [m] of a text artist as the renderer lays it out."""
    extent = text.get_window_extent(renderer).transformed(ax.transData.inverted())
    return float(extent.width), float(extent.height)


def _draw_time_labels(ax: Axes, run: RunRecord, idx: np.ndarray, footprints: list[_Box]) -> None:
    """Label the snapshots with their times, beside their roads, in order, touching nothing.

    Each vehicle's labels go on one side of its road (:func:`_preferred_side`), each to the
    best of :func:`_candidates`: inside the axes, clear of every footprint, every drawn line
    (paths, crossing and yield lines, the conflict point) and every other label, in time order
    along the path. Text extents come from the renderer, so the figure must be laid out. The
    first and last label of each vehicle are placed first and may shift further along the
    road. A label with no such place is left out (the snapshots are evenly spaced in time, so
    its neighbours date it).
    """
    renderer = ax.figure.canvas.get_renderer()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    scene_ = _scenario(run)
    cx, cy = scene_.av.xy(0.0)
    lines, half_width = _line_points(ax)
    scene = _Scene((x0, y0, x1, y1), footprints, lines, _LINE_PAD_M + half_width,
                   {who: _path_points(run, who) for who in ("hv", "av")},
                   (float(cx), float(cy), scene_.min_dist_m), [], {"hv": {}, "av": {}})
    length = run.config.vehicle.length_m
    # The artists are made in time order (the figure lists them so), then placed by priority.
    texts = {(i, who): ax.text(0.0, 0.0, f"{k * _dt(run):g} s", ha="center", va="center",
                               color=_COLORS[who], fontsize=_FONT["note"], zorder=4,
                               gid=f"{who}-time-label")
             for i, k in enumerate(idx) for who in ("hv", "av")}
    sizes = {key: _label_size(ax, text, renderer) for key, text in texts.items()}
    sides = {who: _preferred_side(run, who, idx, [sizes[i, who] for i in range(idx.size)], scene)
             for who in ("hv", "av")}
    ends = {0, idx.size - 1}
    for i, who in sorted(texts, key=lambda key: key[0] not in ends):
        text, k = texts[i, who], int(idx[i])
        options = _candidates(run, who, i, k, sizes[i, who], sides[who], scene, length / 2)
        if i in ends and not options:
            options = _candidates(run, who, i, k, sizes[i, who], sides[who], scene, 3 * length)
        best = min(options, default=None)
        if best is None:
            text.remove()
            continue
        scene.labels.append(best.box)
        scene.placed[who][i] = best.along
        text.set_position(((best.box[0] + best.box[2]) / 2, (best.box[1] + best.box[3]) / 2))


# -- figures ------------------------------------------------------------------------------------


def _topview(runs: Sequence[RunRecord], width_in: float, height_in: float,
             every_s: float) -> Figure:
    _check_runs(runs)
    limits = _view_limits(runs)
    titles, subtitle = _titles(runs, width_in)
    fig = _new_figure(width_in, height_in)
    _subtitle(fig, subtitle)
    axes = fig.subplots(1, len(runs), squeeze=False)[0]
    snapshots = []
    for ax, run, title in zip(axes, runs, titles):
        draw_intersection(ax, run, limits)
        idx = snapshot_indices(run, every_s)
        snapshots.append((idx, _draw_snapshots(ax, run, idx)))
        ax.set_title(title, fontsize=_FONT["title"])
        ax.set_xlabel("x [m]", fontsize=_FONT["label"])
        _style(ax, grid=False)
    axes[0].set_ylabel("y [m]", fontsize=_FONT["label"])
    fig.legend(handles=_vehicle_handles(runs) + _scene_handles(runs[0]), loc="outside lower center",
               ncols=2 if len(runs) == 1 else 4, frameon=False, fontsize=_FONT["legend"])
    fig.draw_without_rendering()  # the label placement needs the final axes scale
    for ax, run, (idx, boxes) in zip(axes, runs, snapshots):
        _draw_time_labels(ax, run, idx, boxes)
    return fig


def topview_figure(lfg_run: RunRecord, mpc_run: RunRecord, every_s: float = 1.0) -> Figure:
    """The paper's Fig. 3: both cases seen from above, with snapshots of the vehicles.

    Parameters
    ----------
    lfg_run, mpc_run : RunRecord
        Left: both vehicles use the LFG; right: the AV uses the branch MPC (as in
        :func:`~persuasive.plots.profile.profile_figure`).
    every_s : float, optional
        Time between snapshots [s], rounded to a whole number of steps; default 1 s.

    Returns
    -------
    matplotlib.figure.Figure
        Per run, the scene to scale with equal aspect (:func:`draw_intersection`): at the
        paper's intersection the AV's road along x and the HV's along y, each
        ``lane_width_m`` wide, the crossing lines at ``s = -stop_distance_m``, and the dotted
        safety circle of radius ``min_dist_m``. Each vehicle's centre path is a thin line in
        its colour; its footprint (``length_m`` x ``width_m``, along its path) is drawn every
        ``every_s``, older snapshots fainter, with the time beside it: outside its road, all of
        a vehicle's times on one side of it (mostly the one away from the other vehicle's
        path), in order along it, never over a footprint, a drawn line or another time, and
        inside the axes (shifted along the road where needed; a time with no such place is
        left out). Both panels share one window; the facts both runs share form the
        subtitle.
    """
    return _topview((lfg_run, mpc_run), DOUBLE_COLUMN_IN, 4.0, every_s)


def topview_single(run: RunRecord, every_s: float = 1.0) -> Figure:
    """:func:`topview_figure` for one run of any configuration, one column wide.

    Parameters
    ----------
    run : RunRecord
        Any closed-loop run.
    every_s : float, optional
        Time between snapshots [s]; default 1 s.

    Returns
    -------
    matplotlib.figure.Figure
        One top-view panel, :data:`SINGLE_COLUMN_IN` wide, titled with the case and the run.
    """
    return _topview((run,), SINGLE_COLUMN_IN, 4.3, every_s)
