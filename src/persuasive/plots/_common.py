"""What every figure of :mod:`persuasive.plots` shares: colours, sizes, fonts, titles.

Conventions: HV blue, AV red (:data:`HV_COLOR`, :data:`AV_COLOR`). Time of state index ``k``
is ``k * dt``; the log row ``k`` (decision step ``k``) is taken at the same time, and a
quantity held over a step (role, acceleration) is drawn as a step line over
``[k dt, (k + 1) dt)``. Sizes suit a two-column paper: :data:`DOUBLE_COLUMN_IN` wide for
two-panel figures, :data:`SINGLE_COLUMN_IN` for one.

Besides the constants, this module reads a run for the figures (:func:`crossing_time`,
:func:`belief_column`), names it (:func:`case_title`, :func:`run_label`, the wrapped column
titles) and builds and styles figures with the object API (an explicit Agg canvas, no pyplot).
"""

from __future__ import annotations

import re
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..simulation import RunRecord

#: Colour of the human-driven vehicle.
HV_COLOR = "#1f77b4"
#: Colour of the autonomous vehicle.
AV_COLOR = "#d62728"
#: Width of a figure spanning both columns of a two-column paper [in].
DOUBLE_COLUMN_IN = 7.0
#: Width of a figure in one column of a two-column paper [in].
SINGLE_COLUMN_IN = 3.5

_COLORS = {"hv": HV_COLOR, "av": AV_COLOR}
_FONT = {"label": 8.0, "tick": 7.0, "title": 8.5, "legend": 7.5, "note": 6.5}


# -- reading a run ------------------------------------------------------------------------------


def _dt(run: RunRecord) -> float:
    return run.config.simulation.dt_s


def _state_times(run: RunRecord) -> np.ndarray:
    """Times of the states ``x_0 .. x_N`` [s]: ``k * dt``."""
    return np.arange(run.states.shape[0]) * _dt(run)


def crossing_time(run: RunRecord, who: str) -> float | None:
    """Time at which ``who`` ("av" or "hv") first reaches the crossing line [s], or None.

    The first state index ``k >= 1`` at which the scenario's arrival test is true
    (:meth:`persuasive.scenarios.Scenario.at_line`, Q7 tolerance included), as the time
    ``k * dt``.
    """
    column = {"av": 0, "hv": 2}[who]
    scene = getattr(run, "scenario", None)
    if scene is None:
        from ..scenarios import build_scenario

        scene = build_scenario(run.config)
    arrived = np.flatnonzero(scene.at_line(who, run.states[1:, column]))
    return None if arrived.size == 0 else float((arrived[0] + 1) * _dt(run))


def belief_column(run: RunRecord, who: str) -> str | None:
    """The log column holding ``who``'s probability that the other vehicle leads, or None
    when its policy keeps no belief (e.g. an IDM human or the constant-velocity AV)."""
    for column in (f"{who}_belief_other_leader", f"{who}_belief_hv_leader"):
        if column in run.log:
            return column
    return None


def _has_role(run: RunRecord, who: str) -> bool:
    return f"{who}_role" in run.log


#: How figures name each AV planner and human model.
PLANNER_NAMES = {"lfg": "LFG", "persuasive": "branch MPC", "passive": "passive MPC",
                 "cv": "constant-velocity MPC", "yield": "always yields", "level1": "level-1",
                 "level2": "level-2", "lfg-rule": "LFG, rule's roles"}
HUMAN_NAMES = {"lfg": "LFG", "stubborn": "stubborn LFG", "noisy": "noisy LFG", "idm": "IDM",
               "aggressive": "aggressive", "replay": "replay", "person": "a person"}


def _planner(run: RunRecord) -> str:
    return PLANNER_NAMES.get(run.config.av.kind, run.config.av.kind)


def _human(run: RunRecord) -> str:
    return HUMAN_NAMES.get(run.config.hv.kind, run.config.hv.kind)


def hv_label(runs: Sequence[RunRecord]) -> str:
    """The HV's legend entry for ``runs``: who drives it, e.g. ``"HV (human-driven, IDM)"``,
    ``"HV (driven by a person)"``; the kinds joined with ``/`` when the runs differ."""
    kinds = list(dict.fromkeys(run.config.hv.kind for run in runs))
    if kinds == ["person"]:
        return "HV (driven by a person)"
    if kinds == ["replay"]:
        return "HV (a replayed recording)"
    return f"HV (human-driven, {' / '.join(HUMAN_NAMES.get(k, k) for k in kinds)})"


def _check_runs(runs: Sequence[RunRecord]) -> None:
    for run in runs:
        if not isinstance(run, RunRecord):
            raise TypeError(f"expected a RunRecord, got {type(run).__name__}")


def _step_line(values: np.ndarray) -> np.ndarray:
    """Per-step values with the last repeated, to draw ``N`` held values over ``N + 1`` times."""
    values = np.asarray(values, dtype=float)
    return np.append(values, values[-1])


# -- naming a run -------------------------------------------------------------------------------


def case_title(run: RunRecord) -> str:
    """Short description of who plans what, e.g. ``"HV: LFG, AV: branch MPC"``."""
    return f"HV: {_human(run)}, AV: {_planner(run)}"


def _run_facts(run: RunRecord) -> list[str]:
    c = run.config
    facts = []
    if c.hv.kind in ("lfg", "stubborn", "noisy"):
        facts += [f"HV starts as {c.hv.role}", f"$p_a$ = {c.roles.p_a:g}"]
    if c.av.kind == "persuasive":
        facts.append(rf"$\hat{{p}}_a$ = {c.p_a_hat:g}")
    if c.scenario.kind != "intersection":
        facts.append(c.scenario.kind)
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


# -- building figures ---------------------------------------------------------------------------


def _new_figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _style(ax: Axes, grid: bool = True) -> None:
    ax.tick_params(labelsize=_FONT["tick"], length=2.5, pad=2)
    if grid:
        ax.grid(True, linewidth=0.4, alpha=0.35)


def _subtitle(fig: Figure, text: str) -> None:
    if text:
        fig.suptitle(text, fontsize=_FONT["title"])


def _vehicle_handles(runs: Sequence[RunRecord]) -> list[Any]:
    return [Line2D([], [], color=HV_COLOR, lw=1.6, label=hv_label(runs)),
            Line2D([], [], color=AV_COLOR, lw=1.6, label="AV (autonomous)")]
