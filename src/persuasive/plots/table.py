"""A reproduced table (Table 1 or 2 of the paper) as bars beside the published shares.

:func:`table_figure` reads the summary ``persuasive reproduce`` writes
(:func:`~persuasive.experiments.load_summary`); :func:`table_row_label` names its rows.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..config import ConfigError
from ._common import _COLORS, _FONT, SINGLE_COLUMN_IN, _new_figure, _style


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
