"""Figures and animations of closed-loop runs and of the reproduced tables (issue 5).

This is the only module of the package that imports matplotlib. Every function takes the data
objects the model produces — a :class:`~persuasive.simulation.RunRecord` from
:func:`~persuasive.simulation.simulate`, or a table summary as written by ``persuasive
reproduce`` (:func:`~persuasive.experiments.load_summary`) — and returns a
:class:`matplotlib.figure.Figure` built with the object API: no pyplot state, no ``show()``,
no backend requirement (frames are rendered with an explicit Agg canvas).

Figures:

- :func:`profile_figure` / :func:`profile_single`: the paper's Fig. 2, time profiles of roles,
  beliefs, speeds and accelerations.
- :func:`topview_figure` / :func:`topview_single`: the paper's Fig. 3, the intersection to
  scale with snapshots of both vehicles.
- :func:`table_figure`: a reproduced table beside the published shares.
- :func:`animation_frames` / :func:`animate`: a run as a top-view animation with the beliefs
  and roles shown live.

Conventions: HV blue, AV red (:data:`HV_COLOR`, :data:`AV_COLOR`). Time of state index ``k``
is ``k * dt``; the log row ``k`` (decision step ``k``) is taken at the same time, and a
quantity held over a step (role, acceleration) is drawn as a step line over
``[k dt, (k + 1) dt)``. Every data artist carries a ``gid`` (e.g. ``"hv-speed"``,
``"av-crossing"``) so that it can be found in the figure and in an SVG. Sizes suit a
two-column paper: :data:`DOUBLE_COLUMN_IN` wide for two-panel figures,
:data:`SINGLE_COLUMN_IN` for one. :func:`save_figure` writes PNG, SVG or PDF by extension.
"""

from __future__ import annotations

import re
from numbers import Real
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Rectangle

from ._files import atomic_write
from .config import ConfigError
from .scenario import Intersection
from .simulation import RunRecord

#: Colour of the human-driven vehicle.
HV_COLOR = "#1f77b4"
#: Colour of the autonomous vehicle.
AV_COLOR = "#d62728"
#: Width of a figure spanning both columns of a two-column paper [in].
DOUBLE_COLUMN_IN = 7.0
#: Width of a figure in one column of a two-column paper [in].
SINGLE_COLUMN_IN = 3.5
#: File extensions :func:`save_figure` writes, and those :func:`animate` writes.
FIGURE_EXTENSIONS = (".png", ".svg", ".pdf")
ANIMATION_EXTENSIONS = (".mp4", ".gif")

_COLORS = {"hv": HV_COLOR, "av": AV_COLOR}
_ROAD_COLOR = "0.86"
_FONT = {"label": 8.0, "tick": 7.0, "title": 8.5, "legend": 7.5, "note": 6.5}


# -- reading a run ------------------------------------------------------------------------------


def _dt(run: RunRecord) -> float:
    return run.config.simulation.dt_s


def _state_times(run: RunRecord) -> np.ndarray:
    """Times of the states ``x_0 .. x_N`` [s]: ``k * dt``."""
    return np.arange(run.states.shape[0]) * _dt(run)


def crossing_time(run: RunRecord, who: str) -> float | None:
    """Time at which ``who`` ("av" or "hv") first reaches the crossing line [s], or None.

    The first state index ``k >= 1`` with :meth:`Intersection.at_line` true (the arrival test
    of the outcome, Q7 tolerance included), as the time ``k * dt``.
    """
    column = {"av": 0, "hv": 2}[who]
    arrived = np.flatnonzero(Intersection(run.config).at_line(run.states[1:, column]))
    return None if arrived.size == 0 else float((arrived[0] + 1) * _dt(run))


def belief_column(run: RunRecord, who: str) -> str:
    """The log column holding ``who``'s probability that the other vehicle leads."""
    if who == "hv" or run.config.simulation.av == "lfg":
        return f"{who}_belief_other_leader"
    return "av_belief_hv_leader"


def _has_role(run: RunRecord, who: str) -> bool:
    return f"{who}_role" in run.log


def _planner(run: RunRecord) -> str:
    return "LFG" if run.config.simulation.av == "lfg" else "branch MPC"


def case_title(run: RunRecord) -> str:
    """Short description of who plans what, e.g. ``"HV: LFG, AV: branch MPC"``."""
    return f"HV: LFG, AV: {_planner(run)}"


def _run_facts(run: RunRecord) -> list[str]:
    c = run.config
    facts = [f"HV starts as {c.simulation.hv_role}", f"$p_a$ = {c.roles.p_a:g}"]
    if c.simulation.av == "mpc":
        facts.append(rf"$\hat{{p}}_a$ = {c.p_a_hat:g}")
    return facts + [f"seed {run.seed}", f"{c.mode} mode"]


def run_label(run: RunRecord) -> str:
    """One-line identity of a run: initial role, ``p_a`` (and ``p̂_a``), seed and mode."""
    return ", ".join(_run_facts(run))


def _visible_len(text: str) -> int:
    """Length of ``text`` as rendered, roughly: mathtext commands and braces do not count."""
    return len(re.sub(r"\\[a-zA-Z]+|[${}_^]", "", text))


def _wrap(parts: Sequence[str], width_in: float) -> str:
    """Join ``parts`` with ", ", starting a new line where a line would pass ``width_in``."""
    max_chars = int(width_in * 72.0 * 0.92 / (0.56 * _FONT["title"]))
    lines: list[str] = []
    for part in parts:
        if lines and _visible_len(lines[-1] + ", " + part) <= max_chars:
            lines[-1] += ", " + part
        else:
            lines.append(part)
    return "\n".join(lines)


def _titles(runs: Sequence[RunRecord], width_in: float) -> tuple[list[str], str]:
    """Column titles and a subtitle: the facts all runs share go once into the subtitle.

    A single run gets its case and all its facts in its title and no subtitle; several runs
    get ``(a)``, ``(b)``, ... with the case and the facts only that run has. Lines are
    wrapped to the width of a column (``width_in`` is the figure's).
    """
    facts = [_run_facts(r) for r in runs]
    column_in = width_in / len(runs) - 0.4
    if len(runs) == 1:
        return [f"{case_title(runs[0])}\n{_wrap(facts[0], column_in)}"], ""
    common = [f for f in facts[0] if all(f in other for other in facts[1:])]
    titles = []
    for j, (run, own) in enumerate(zip(runs, facts)):
        head = f"({chr(ord('a') + j)}) {case_title(run)}"
        titles.append(_wrap([head, *[f for f in own if f not in common]], column_in))
    return titles, _wrap(common, width_in)


def _step_line(values: np.ndarray) -> np.ndarray:
    """Per-step values with the last repeated, to draw ``N`` held values over ``N + 1`` times."""
    values = np.asarray(values, dtype=float)
    return np.append(values, values[-1])


# -- shared drawing helpers ---------------------------------------------------------------------


def _new_figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _style(ax: Axes, grid: bool = True) -> None:
    ax.tick_params(labelsize=_FONT["tick"], length=2.5, pad=2)
    if grid:
        ax.grid(True, linewidth=0.4, alpha=0.35)


def _mark_crossings(ax: Axes, run: RunRecord) -> None:
    for who in ("hv", "av"):
        t = crossing_time(run, who)
        if t is not None:
            ax.axvline(t, color=_COLORS[who], linestyle="--", linewidth=0.9, alpha=0.9,
                       gid=f"{who}-crossing")


def _vehicle_handles() -> list[Any]:
    return [Line2D([], [], color=HV_COLOR, lw=1.6, label="HV (human-driven, LFG)"),
            Line2D([], [], color=AV_COLOR, lw=1.6, label="AV (autonomous)")]


def _check_runs(runs: Sequence[RunRecord]) -> None:
    for run in runs:
        if not isinstance(run, RunRecord):
            raise TypeError(f"expected a RunRecord, got {type(run).__name__}")


# -- Fig. 2: time profiles ----------------------------------------------------------------------

#: Rows of the profile figure: (key, y label).
PROFILE_ROWS = (("role", "role"), ("belief", "P(other = leader)"), ("speed", "speed [m/s]"),
                ("accel", "accel. [m/s$^2$]"))


def _profile_column(axes: Sequence[Axes], run: RunRecord) -> None:
    """Draw one run's four profile rows into ``axes`` (top to bottom)."""
    ax_role, ax_belief, ax_speed, ax_accel = axes
    t_states = _state_times(run)
    t_log = run.log["t_s"]
    for who in ("hv", "av"):
        color = _COLORS[who]
        if _has_role(run, who):
            level = (run.log[f"{who}_role"] == "leader").astype(float)
            # The HV's line is drawn wider underneath, so that equal roles stay visible.
            ax_role.plot(t_states, _step_line(level), drawstyle="steps-post", color=color,
                         lw=2.6 if who == "hv" else 1.3, zorder=2 if who == "hv" else 3,
                         gid=f"{who}-role")
        ax_belief.plot(t_log, run.log[belief_column(run, who)], color=color, gid=f"{who}-belief")
        ax_speed.plot(t_states, run.states[:, 1 if who == "av" else 3], color=color,
                      gid=f"{who}-speed")
        ax_accel.plot(t_states, _step_line(run.log[f"{who}_accel_mps2"]),
                      drawstyle="steps-post", color=color, gid=f"{who}-accel")
    if not _has_role(run, "av"):
        # Above the L level, where only the crossing markers pass.
        ax_role.text(0.99, 0.96, f"AV ({_planner(run)}): no role",
                     transform=ax_role.transAxes, ha="right", va="top",
                     fontsize=_FONT["note"], color=AV_COLOR, style="italic", zorder=5,
                     bbox=dict(fc="white", ec="none", alpha=0.9, pad=1.5))
    veh = run.config.vehicle
    ax_role.set_ylim(-0.35, 1.35)
    ax_role.set_yticks([0.0, 1.0], ["F", "L"])
    ax_belief.set_ylim(-0.06, 1.06)
    ax_belief.set_yticks([0.0, 0.5, 1.0])
    ax_speed.set_ylim(0.0, max(veh.v_max_mps, float(np.max(run.states[:, [1, 3]]))) + 0.5)
    ax_accel.set_ylim(veh.u_min_mps2 - 0.3, veh.u_max_mps2 + 0.3)
    ax_accel.set_xlim(0.0, t_states[-1])
    for ax in axes:
        _mark_crossings(ax, run)
        _style(ax)


def _subtitle(fig: Figure, text: str) -> None:
    if text:
        fig.suptitle(text, fontsize=_FONT["title"])


def _profile(runs: Sequence[RunRecord], width_in: float) -> Figure:
    _check_runs(runs)
    n = len(runs)
    titles, subtitle = _titles(runs, width_in)
    fig = _new_figure(width_in, 5.2)
    _subtitle(fig, subtitle)
    axes = fig.subplots(len(PROFILE_ROWS), n, sharex=True, sharey="row", squeeze=False)
    for j, (run, title) in enumerate(zip(runs, titles)):
        _profile_column(axes[:, j], run)
        axes[0, j].set_title(title, fontsize=_FONT["title"])
        axes[-1, j].set_xlabel("time [s]", fontsize=_FONT["label"])
    for i, (_, label) in enumerate(PROFILE_ROWS):
        axes[i, 0].set_ylabel(label, fontsize=_FONT["label"])
    handles = _vehicle_handles() + [
        Line2D([], [], color="0.3", ls="--", lw=0.9, label="reaches the crossing line")]
    fig.legend(handles=handles, loc="outside lower center", ncols=2 if n == 1 else 3,
               frameon=False, fontsize=_FONT["legend"])
    return fig


def profile_figure(lfg_run: RunRecord, mpc_run: RunRecord) -> Figure:
    """The paper's Fig. 2: role, belief, speed and acceleration over time, two cases side by side.

    Parameters
    ----------
    lfg_run : RunRecord
        Left column: both vehicles use the LFG (``simulation.av = "lfg"``).
    mpc_run : RunRecord
        Right column: the HV uses the LFG and the AV the persuasive branch MPC
        (``simulation.av = "mpc"``).

    Returns
    -------
    matplotlib.figure.Figure
        Four rows sharing the time axis [s], one column per run, HV blue and AV red:

        1. the role each LFG player holds at each step, a step line at the levels L (1) and F
           (0) (the MPC AV has none);
        2. the probability each vehicle assigns to the *other* being the leader (the HV's
           ``P(AV = L)``, the AV's ``P(HV = L)``), after the step's Bayes update;
        3. the speeds ``v`` [m/s] of the states ``x_0 .. x_N``;
        4. the applied accelerations [m/s^2], held over each step.

        A dashed vertical line in a vehicle's colour on every row marks the time it first
        reaches the crossing line. The column titles name the case, the facts both runs
        share form the subtitle, and the legend sits at the bottom.
    """
    return _profile((lfg_run, mpc_run), DOUBLE_COLUMN_IN)


def profile_single(run: RunRecord) -> Figure:
    """The four rows of :func:`profile_figure` for one run of any configuration.

    Parameters
    ----------
    run : RunRecord
        Any closed-loop run (LFG or MPC AV, any parameters).

    Returns
    -------
    matplotlib.figure.Figure
        One column, :data:`SINGLE_COLUMN_IN` wide, titled with the case and the run.
    """
    return _profile((run,), SINGLE_COLUMN_IN + 0.3)


# -- Fig. 3: top view ---------------------------------------------------------------------------


def _vehicle_xy(run: RunRecord, who: str, k: np.ndarray | int) -> tuple[Any, Any]:
    """Centre ``(x, y)`` [m] of ``who`` at state index ``k``: the AV on y = 0, the HV on x = 0."""
    s = run.states[k, 0 if who == "av" else 2]
    zero = np.zeros_like(s)
    return (s, zero) if who == "av" else (zero, s)


def _footprint(run: RunRecord, who: str) -> tuple[float, float]:
    """Footprint ``(extent along x, extent along y)`` [m] of ``who``."""
    veh = run.config.vehicle
    return (veh.length_m, veh.width_m) if who == "av" else (veh.width_m, veh.length_m)


def _vehicle_patch(run: RunRecord, who: str, k: int, **kwargs: Any) -> Rectangle:
    (x, y), (wx, wy) = _vehicle_xy(run, who, k), _footprint(run, who)
    return Rectangle((x - wx / 2, y - wy / 2), wx, wy, **kwargs)


def _view_limits(runs: Sequence[RunRecord]) -> tuple[float, float]:
    """One square window (same range for x and y) holding every position of every run."""
    s = np.concatenate([r.states[:, [0, 2]].ravel() for r in runs])
    margin = max(r.config.vehicle.length_m for r in runs) + 2.0
    return float(min(s.min(), -margin)) - margin, float(max(s.max(), margin)) + margin


def draw_intersection(ax: Axes, run: RunRecord, limits: tuple[float, float]) -> None:
    """The scene to scale: both roads, the crossing lines and the safety circle.

    Each road is ``lane_width_m`` wide and centred on its axis; the crossing line of each
    approach is drawn across its road at ``s = -stop_distance_m``; the dotted circle of radius
    ``min_dist_m`` around the conflict point is the safe-set boundary for the other vehicle's
    centre when one vehicle is at the conflict point.
    """
    veh, scene = run.config.vehicle, Intersection(run.config)
    lo, hi, half = limits[0], limits[1], veh.lane_width_m / 2
    ax.add_patch(Rectangle((lo, -half), hi - lo, 2 * half, color=_ROAD_COLOR, lw=0, zorder=0,
                           gid="road-av"))
    ax.add_patch(Rectangle((-half, lo), 2 * half, hi - lo, color=_ROAD_COLOR, lw=0, zorder=0,
                           gid="road-hv"))
    line = -scene.stop_distance_m
    for xs, ys, who in (([line, line], [-half, half], "av"), ([-half, half], [line, line], "hv")):
        ax.plot(xs, ys, color="0.15", lw=1.4, solid_capstyle="butt", zorder=1,
                gid=f"{who}-crossing-line")
    ax.add_patch(Circle((0.0, 0.0), scene.min_dist_m, fill=False, ls=":", lw=0.9, ec="0.25",
                        zorder=1, gid="safety-circle"))
    ax.plot([0.0], [0.0], marker="+", color="0.25", ms=5, mew=0.8, zorder=1,
            gid="conflict-point")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")


def snapshot_indices(run: RunRecord, every_s: float) -> np.ndarray:
    """State indices ``0, m, 2m, ...`` with ``m = round(every_s / dt)`` (at least 1)."""
    if isinstance(every_s, bool) or not isinstance(every_s, Real) or not np.isfinite(every_s) \
            or every_s <= 0:
        raise ConfigError(f"every = {every_s!r} is out of range; allowed: > 0 seconds")
    m = max(1, int(round(every_s / _dt(run))))
    return np.arange(0, run.states.shape[0], m)


_Box = tuple[float, float, float, float]  # x0, y0, x1, y1 [m]


def _overlap(a: _Box, b: _Box) -> float:
    """Area shared by two boxes [m^2]."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _text_box(x: float, y: float, text: str, ha: str, va: str, m_per_pt: float) -> _Box:
    """Estimated extent of a label of ``_FONT["note"]`` points anchored at ``(x, y)`` [m]."""
    size = _FONT["note"] * m_per_pt
    w, h = 0.62 * size * len(text), 1.25 * size
    x0 = {"left": x, "center": x - w / 2, "right": x - w}[ha]
    y0 = {"bottom": y, "center": y - h / 2, "top": y - h}[va]
    return x0, y0, x0 + w, y0 + h


def _label_candidates(run: RunRecord, who: str, k: int) -> list[tuple[float, float, str, str]]:
    """Anchors ``(x, y, ha, va)`` of a snapshot's time label, the preferred one first.

    AV labels go above its road (below when that is crowded), HV labels right of its road
    (left when crowded): the preferred sides look away from the other vehicle's approach.
    """
    x, y = _vehicle_xy(run, who, k)
    veh = run.config.vehicle
    # Just outside the road, clear of the crossing lines drawn across it.
    off = max(veh.width_m, veh.lane_width_m) / 2 + 0.3
    if who == "av":
        return [(x, y + off, "center", "bottom"), (x, y - off, "center", "top")]
    return [(x + off, y, "left", "center"), (x - off, y, "right", "center")]


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
            x0, y0 = patch.get_xy()
            boxes.append((x0, y0, x0 + patch.get_width(), y0 + patch.get_height()))
    return boxes


def _draw_time_labels(ax: Axes, run: RunRecord, idx: np.ndarray, footprints: list[_Box]) -> None:
    """Label the snapshots with their times, each on the side where it collides least.

    Text extents are estimated from the font size and the axes' scale (the figure must be
    laid out). A label that would overlap another label on both sides is left out (the
    snapshots are evenly spaced in time, so its neighbours date it), except the first and
    last of each vehicle; one that only overlaps footprints gets a white backing.
    """
    m_per_pt = np.diff(ax.get_xlim())[0] / (ax.get_window_extent().width * 72.0 / ax.figure.dpi)
    labels: list[_Box] = []
    for i, k in enumerate(idx):
        for who in ("hv", "av"):
            text = f"{k * _dt(run):g} s"
            options = [(*o, _text_box(*o[:2], text, *o[2:], m_per_pt))
                       for o in _label_candidates(run, who, int(k))]
            # Cost: overlap with other labels first, then with footprints (ties: preferred).
            costs = [(sum(_overlap(box, b) for b in labels),
                      sum(_overlap(box, b) for b in footprints)) for *_, box in options]
            best = min(range(len(options)), key=costs.__getitem__)
            if costs[best][0] > 0 and 0 < i < idx.size - 1:
                continue
            x, y, ha, va, box = options[best]
            labels.append(box)
            backing = dict(fc="white", ec="none", alpha=0.75, pad=0.6) if any(costs[best]) \
                else None
            ax.text(x, y, text, ha=ha, va=va, color=_COLORS[who], fontsize=_FONT["note"],
                    zorder=4, bbox=backing, gid=f"{who}-time-label")


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
    handles = _vehicle_handles() + [
        Line2D([], [], color="0.15", lw=1.4, label="crossing line"),
        Line2D([], [], color="0.25", lw=0.9, ls=":",
               label=f"safe distance {runs[0].config.vehicle.min_dist_m:g} m")]
    fig.legend(handles=handles, loc="outside lower center", ncols=2 if len(runs) == 1 else 4,
               frameon=False, fontsize=_FONT["legend"])
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
        :func:`profile_figure`).
    every_s : float, optional
        Time between snapshots [s], rounded to a whole number of steps; default 1 s.

    Returns
    -------
    matplotlib.figure.Figure
        Per run, the intersection to scale with equal aspect (:func:`draw_intersection`):
        the AV's road along x and the HV's along y, each ``lane_width_m`` wide, the crossing
        lines at ``s = -stop_distance_m``, and the dotted safety circle of radius
        ``min_dist_m``. Each vehicle's centre path is a thin line in its colour; its
        footprint (``length_m`` x ``width_m``, along its road) is drawn every ``every_s``,
        older snapshots fainter, with the time beside it (AV labels above its road, HV
        labels right of its road, on the other side where they would collide; a label that
        collides with other labels on both sides is left out). Both panels share one
        window; the facts both runs share form the subtitle.
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


# -- reproduced tables --------------------------------------------------------------------------


def table_row_label(row: dict[str, Any]) -> str:
    """Label of a summary row, e.g. ``"L, p_a = 1.00, p̂_a = 0.98"`` (in mathtext)."""
    text = f"{'L' if row['hv_role'] == 'leader' else 'F'}, $p_a$ = {row['pa']:.2f}"
    if row.get("pa_hat") is not None:
        text += rf", $\hat{{p}}_a$ = {row['pa_hat']:.2f}"
    return text


def table_figure(summary: dict[str, Any]) -> Figure:
    """A reproduced table as grouped horizontal bars, with the published shares marked.

    Parameters
    ----------
    summary : dict
        One table's summary as written to ``<results dir>/summary.json`` by ``persuasive
        reproduce`` (:func:`~persuasive.experiments.summarize`): ``table``, ``mode``,
        ``seeds`` and ``rows`` with ``hv_role``, ``pa``, ``pa_hat``, ``av_first_pct``,
        ``hv_first_pct``, ``published_av_first_pct``, ``published_hv_first_pct``.

    Returns
    -------
    matplotlib.figure.Figure
        One bar group per table row, in the paper's order from the top, labelled by the HV's
        initial role (L/F), ``p_a`` and (Table 2) ``p̂_a``: the share of runs in which the
        AV (red) and the HV (blue) reached the crossing line first [%]. Black ticks mark
        the published shares. Runs in which both arrived in the same step, or neither
        arrived, are in neither bar.
    """
    try:
        rows = list(summary["rows"])
        table, mode, seeds = summary["table"], summary["mode"], summary["seeds"]
    except (KeyError, TypeError) as exc:
        raise ConfigError(f"summary lacks the entry {exc}; expected a summary.json written by "
                          "'persuasive reproduce'") from None
    if not rows:
        raise ConfigError(f"summary of {table!r} has no rows")
    n = len(rows)
    y = np.arange(n, dtype=float)
    h = 0.38
    fig = _new_figure(SINGLE_COLUMN_IN + 1.0, 1.3 + 0.27 * n)
    ax = fig.subplots()
    bars = {}
    for who, offset in (("av", -h / 2), ("hv", h / 2)):
        values = [float(r[f"{who}_first_pct"]) for r in rows]
        bars[who] = ax.barh(y + offset, values, height=h, color=_COLORS[who],
                            label=f"{who.upper()} first (reproduced)", gid=f"{who}-first")
        published = [float(r[f"published_{who}_first_pct"]) for r in rows]
        ax.plot(published, y + offset, ls="none", marker="|", ms=7.5, mew=1.6, color="black",
                gid=f"{who}-published")
    ax.set_yticks(y, [table_row_label(r) for r in rows])
    ax.set_ylim(n - 0.5, -0.5)  # the paper's first row on top
    ax.set_xlim(-2.5, 102.5)  # room for the markers of 0 % and 100 %, clear of the frame
    ax.set_xticks(np.arange(0, 101, 20))
    ax.set_xlabel("first at the crossing line [% of runs]", fontsize=_FONT["label"])
    name = f"Table {table[len('table'):]}" if str(table).startswith("table") else str(table)
    ax.set_title(f"{name}, {mode} mode, seeds 1..{seeds} per row", fontsize=_FONT["title"])
    _style(ax)
    ax.grid(axis="y", visible=False)
    handles = [bars["av"], bars["hv"],
               Line2D([], [], ls="none", marker="|", ms=7.5, mew=1.6, color="black",
                      label="published")]
    fig.legend(handles=handles, loc="outside lower center", ncols=3, frameon=False,
               fontsize=_FONT["legend"])
    return fig


# -- animation ----------------------------------------------------------------------------------


class _AnimationScene:
    """The animation's figure, built once and updated in place frame by frame."""

    def __init__(self, run: RunRecord, width_in: float, height_in: float, dpi: float):
        self.run = run
        self.fig = Figure(figsize=(width_in, height_in), dpi=dpi, layout="constrained")
        self.canvas = FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(2, 2, width_ratios=(1.0, 1.05), height_ratios=(1.0, 0.62))
        self.ax_top = self.fig.add_subplot(grid[:, 0])
        self.ax_belief = self.fig.add_subplot(grid[0, 1])
        self.ax_text = self.fig.add_subplot(grid[1, 1])
        self.ax_text.axis("off")
        limits = _view_limits((run,))
        draw_intersection(self.ax_top, run, limits)
        self.ax_top.set_xlabel("x [m]", fontsize=_FONT["label"])
        self.ax_top.set_ylabel("y [m]", fontsize=_FONT["label"])
        self.ax_top.set_title(case_title(run), fontsize=_FONT["title"])
        self.fig.suptitle(run_label(run), fontsize=_FONT["title"])
        _style(self.ax_top, grid=False)
        self.paths, self.cars, self.beliefs = {}, {}, {}
        for who in ("hv", "av"):
            color = _COLORS[who]
            self.paths[who] = self.ax_top.plot([], [], color=color, lw=1.0, zorder=2,
                                               gid=f"{who}-path")[0]
            self.cars[who] = _vehicle_patch(run, who, 0, fc=color, ec="black", lw=0.5, zorder=3,
                                            gid=f"{who}-vehicle")
            self.ax_top.add_patch(self.cars[who])
            other = "AV" if who == "hv" else "HV"
            self.beliefs[who] = self.ax_belief.plot(
                [], [], color=color, label=f"{who.upper()}: P({other} = leader)",
                gid=f"{who}-belief")[0]
        self.ax_belief.set_xlim(0.0, _state_times(run)[-1])
        self.ax_belief.set_ylim(-0.06, 1.06)
        self.ax_belief.set_xlabel("time [s]", fontsize=_FONT["label"])
        self.ax_belief.set_ylabel("belief", fontsize=_FONT["label"])
        self.ax_belief.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=2,
                              frameon=False, fontsize=_FONT["legend"])
        _style(self.ax_belief)
        self.text = self.ax_text.text(0.02, 0.98, "", transform=self.ax_text.transAxes,
                                      ha="left", va="top", fontsize=_FONT["label"],
                                      family="monospace", linespacing=1.5)
        self.crossing = {who: crossing_time(run, who) for who in ("hv", "av")}
        # Blitting: draw the static scene once, freeze the layout, then redraw only the
        # moving artists over a copy of that background in each frame.
        self.moving = [*self.paths.values(), *self.cars.values(), *self.beliefs.values(),
                       self.text]
        for artist in self.moving:
            artist.set_animated(True)
        self.canvas.draw()
        self.fig.set_layout_engine("none")
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)

    def _status(self, k: int) -> str:
        run, t = self.run, float(self.run.log["t_s"][k])
        lines = [f"t = {t:4.1f} s   (step {k})"]
        for who in ("hv", "av"):
            name = who.upper()
            if _has_role(run, who):
                lines.append(f"{name} role: {run.log[f'{who}_role'][k]}")
            else:
                lines.append(f"{name}: {_planner(run)}, no role")
        for who in ("hv", "av"):
            tc = self.crossing[who]
            state = f"at {tc:.1f} s" if tc is not None and tc <= t else "not yet"
            lines.append(f"{who.upper()} at the crossing line: {state}")
        return "\n".join(lines)

    def render(self, k: int) -> np.ndarray:
        """The frame of decision step ``k``: RGB ``(height, width, 3)`` uint8."""
        run = self.run
        t_log = run.log["t_s"][: k + 1]
        for who in ("hv", "av"):
            x, y = _vehicle_xy(run, who, np.arange(k + 1))
            self.paths[who].set_data(x, y)
            (cx, cy), (wx, wy) = _vehicle_xy(run, who, k), _footprint(run, who)
            self.cars[who].set_xy((cx - wx / 2, cy - wy / 2))
            self.beliefs[who].set_data(t_log, run.log[belief_column(run, who)][: k + 1])
        self.text.set_text(self._status(k))
        self.canvas.restore_region(self.background)
        for artist in self.moving:
            self.fig.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


def animation_frames(run: RunRecord, dpi: float = 120.0, width_in: float = 8.0,
                     height_in: float = 4.0) -> Iterator[np.ndarray]:
    """Render a run as frames: one per decision step (``len(run.log["step"])`` frames).

    Parameters
    ----------
    run : RunRecord
        The run to animate.
    dpi, width_in, height_in : float, optional
        Frame resolution [dots/in] and size [in]; the defaults give 960 x 480 pixels.

    Yields
    ------
    numpy.ndarray
        Frame ``k``: RGB ``(height_px, width_px, 3)`` uint8. Left, the top view of
        :func:`draw_intersection` with both vehicles at state ``x_k`` and their paths so far;
        right, the beliefs of both vehicles that the other leads, up to step ``k``, and below
        them the time, each LFG player's current role and whether each vehicle has reached
        the crossing line.
    """
    scene = _AnimationScene(run, width_in, height_in, dpi)
    for k in range(len(run.log["step"])):
        yield scene.render(k)


def _even(frame: np.ndarray) -> np.ndarray:
    """Pad a frame with white to even height and width (H.264 in yuv420p needs them)."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), constant_values=255)


def _suffix(path: Path, allowed: tuple[str, ...], what: str) -> str:
    ext = path.suffix.lower()
    if ext not in allowed:
        raise ConfigError(f"{what} file {str(path)!r} has an unsupported extension "
                          f"{ext or '(none)'!r}; allowed: {' | '.join(allowed)}")
    return ext


def check_figure_path(path: str | Path) -> str:
    """The lower-case extension of ``path`` if :func:`save_figure` writes it, else ConfigError."""
    return _suffix(Path(path), FIGURE_EXTENSIONS, "figure")


def check_animation_path(path: str | Path) -> str:
    """The lower-case extension of ``path`` if :func:`animate` writes it, else ConfigError."""
    return _suffix(Path(path), ANIMATION_EXTENSIONS, "animation")


def save_figure(fig: Figure, path: str | Path, dpi: float = 300.0) -> Path:
    """Save ``fig`` as PNG, SVG or PDF, chosen by the extension of ``path``, atomically.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        Target file; ``.png``, ``.svg`` or ``.pdf`` (case-insensitive). Missing parent
        folders are created.
    dpi : float, optional
        Resolution of PNG output [dots/in]; default 300.

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    ext = check_figure_path(path)
    atomic_write(path, lambda tmp: fig.savefig(tmp, format=ext[1:], dpi=dpi,
                                                facecolor="white"))
    return path


def animate(run: RunRecord, path: str | Path, fps: int = 10, dpi: float = 120.0) -> Path:
    """Write the animation of :func:`animation_frames` as MP4 (H.264) or GIF, by extension.

    Parameters
    ----------
    run : RunRecord
        The run to animate; one frame per decision step.
    path : str or Path
        Target file, ``.mp4`` or ``.gif``; written to a temporary sibling, then renamed.
    fps : int, optional
        Frames per second; default 10, i.e. real time for ``dt = 0.1 s``.
    dpi : float, optional
        Frame resolution [dots/in]; default 120 (960 x 480 pixels).

    Returns
    -------
    Path
        The written file.
    """
    import imageio.v2 as iio2
    import imageio.v3 as iio3

    path = Path(path)
    ext = check_animation_path(path)
    if isinstance(fps, bool) or not isinstance(fps, (int, np.integer)) or fps < 1:
        raise ConfigError(f"fps = {fps!r} is out of range; allowed: integer >= 1")
    frames = (_even(f) for f in animation_frames(run, dpi=dpi))

    def write(tmp: Path) -> None:
        if ext == ".mp4":
            with iio2.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                 pixelformat="yuv420p", macro_block_size=2,
                                 ffmpeg_log_level="error") as writer:
                for frame in frames:
                    writer.append_data(frame)
        else:
            iio3.imwrite(tmp, np.stack(list(frames)), extension=".gif", plugin="pillow",
                         duration=1000.0 / fps, loop=0)

    atomic_write(path, write)
    return path


__all__ = [
    "ANIMATION_EXTENSIONS",
    "AV_COLOR",
    "DOUBLE_COLUMN_IN",
    "FIGURE_EXTENSIONS",
    "HV_COLOR",
    "PROFILE_ROWS",
    "SINGLE_COLUMN_IN",
    "animate",
    "animation_frames",
    "belief_column",
    "case_title",
    "check_animation_path",
    "check_figure_path",
    "crossing_time",
    "draw_intersection",
    "profile_figure",
    "profile_single",
    "run_label",
    "save_figure",
    "snapshot_indices",
    "table_figure",
    "table_row_label",
    "topview_figure",
    "topview_single",
]
