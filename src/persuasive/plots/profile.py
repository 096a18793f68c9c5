"""The paper's Fig. 2: time profiles of roles, beliefs, speeds and accelerations.

:func:`profile_figure` draws the two cases of the paper side by side (both vehicles LFG; LFG
HV and branch-MPC AV), :func:`profile_single` one run of any configuration. The rows are
:data:`PROFILE_ROWS`; every data artist carries a ``gid`` such as ``"hv-speed"`` or
``"av-crossing"``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..simulation import RunRecord
from ._common import (_COLORS, _FONT, DOUBLE_COLUMN_IN, SINGLE_COLUMN_IN, _check_runs,
                      _has_role, _human, _new_figure, _planner, _state_times, _step_line,
                      _style, _subtitle, _titles, _vehicle_handles, belief_column,
                      crossing_time)

#: The log column of a fitted run holding the human's smoothed ``P(role = L)``
#: (``persuasive fit --out FILE.parquet``).
FIT_COLUMN = "hv_fit_p_leader"

#: Rows of the profile figure: (key, y label).
PROFILE_ROWS = (("role", "role"), ("belief", "P(other = leader)"), ("speed", "speed [m/s]"),
                ("accel", "accel. [m/s$^2$]"))


def _mark_crossings(ax: Axes, run: RunRecord) -> None:
    for who in ("hv", "av"):
        t = crossing_time(run, who)
        if t is not None:
            ax.axvline(t, color=_COLORS[who], linestyle="--", linewidth=0.9, alpha=0.9,
                       gid=f"{who}-crossing")


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
        column = belief_column(run, who)
        if column is not None:
            ax_belief.plot(t_log, run.log[column], color=color, gid=f"{who}-belief")
        ax_speed.plot(t_states, run.states[:, 1 if who == "av" else 3], color=color,
                      gid=f"{who}-speed")
        ax_accel.plot(t_states, _step_line(run.log[f"{who}_accel_mps2"]),
                      drawstyle="steps-post", color=color, gid=f"{who}-accel")
    if FIT_COLUMN in run.log:
        # the human's role as a fit of its driving infers it: P(role = L), smoothed
        ax_role.plot(t_states, _step_line(run.log[FIT_COLUMN]), drawstyle="steps-post",
                     color=_COLORS["hv"], lw=1.0, ls=":", zorder=4, gid="hv-role-fit")
    # A vehicle whose driver holds no role (a person, a replay, IDM, the MPC AV, ...) says so,
    # above the L level where only the crossing markers pass: the HV at the left, the AV at
    # the right; a human whose role a fit inferred has the fitted line instead.
    for who, name, x, ha in (("hv", _human(run), 0.01, "left"),
                             ("av", _planner(run), 0.99, "right")):
        if not _has_role(run, who) and not (who == "hv" and FIT_COLUMN in run.log):
            ax_role.text(x, 0.96, f"{who.upper()} ({name}): no role",
                         transform=ax_role.transAxes, ha=ha, va="top",
                         fontsize=_FONT["note"], color=_COLORS[who], style="italic", zorder=5,
                         bbox=dict(fc="white", ec="none", alpha=0.9, pad=1.5),
                         gid=f"{who}-no-role")
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
    handles = _vehicle_handles(runs) + [
        Line2D([], [], color="0.3", ls="--", lw=0.9, label="reaches the crossing line")]
    if any(FIT_COLUMN in run.log for run in runs):
        handles.append(Line2D([], [], color=_COLORS["hv"], ls=":", lw=1.0,
                              label="HV P(leader), fitted"))
    fig.legend(handles=handles, loc="outside lower center", ncols=2 if n == 1 else 3,
               frameon=False, fontsize=_FONT["legend"])
    return fig


def profile_figure(lfg_run: RunRecord, mpc_run: RunRecord) -> Figure:
    """The paper's Fig. 2: role, belief, speed and acceleration over time, two cases side by side.

    Parameters
    ----------
    lfg_run : RunRecord
        Left column: both vehicles use the LFG (``av.kind = "lfg"``).
    mpc_run : RunRecord
        Right column: the HV uses the LFG and the AV the persuasive branch MPC
        (``av.kind = "persuasive"``).

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
