"""A comparison of planners and humans (``persuasive compare``) as one figure.

:func:`compare_figure` draws, from a comparison's summary and runs: left, the outcome matrix, AV
planners by human models, each cell coloured by the share of runs in which the AV reached its line
first and labelled with that share, its 95 % interval (when the cells leave room) and the number of
collisions the AV caused; with several shield settings (``compare --shield``) each planner has a
row per setting; right, box plots of the AV's and the human's delays per pair (time to leave the
conflict zone minus the free-flow time; runs where a vehicle never cleared are left out and
counted). A pair whose delays are all zero, or undefined (the vehicle never cleared), says "0" or
"n/a" beside its empty box.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ._common import _FONT, AV_COLOR, DOUBLE_COLUMN_IN, HV_COLOR, _new_figure, _style


def compare_figure(summary: dict[str, Any], runs) -> Figure:
    """The comparison's figure (see the module docstring).

    Parameters
    ----------
    summary : dict
        ``summary.json`` of a comparison (:func:`persuasive.studies.compare.load_summary`).
    runs : pandas.DataFrame
        Its runs (:func:`persuasive.sweep.load` of the same folder).
    """
    avs, hvs = summary["av_kinds"], summary["hv_kinds"]
    shields = summary.get("shields", ["off"])
    # one row per planner, or per (planner, shield) when the comparison has a shield axis
    lines = [(av, sh) for av in avs for sh in shields]
    names = [f"{av}\n{sh}" if len(shields) > 1 else av for av, sh in lines]
    rows = {(r["av"], r.get("shield", shields[0]), r["hv"]): r for r in summary["rows"]}
    fig = _new_figure(DOUBLE_COLUMN_IN, 1.6 + 0.5 * max(len(lines), 3))
    roomy = len(hvs) <= 5  # narrower cells have no room for the interval
    ax_m, ax_b = fig.subplots(1, 2, width_ratios=(1.0, 1.25) if roomy else (1.4, 1.0))
    share = np.full((len(lines), len(hvs)), np.nan)
    for i, (av, sh) in enumerate(lines):
        for j, hv in enumerate(hvs):
            if (av, sh, hv) in rows:
                share[i, j] = rows[(av, sh, hv)]["av_first_pct"]
    image = ax_m.imshow(share, cmap="RdBu_r", vmin=0.0, vmax=100.0, aspect="auto",
                        gid="outcome-matrix")
    size = _FONT["note"] - (0.5 if roomy else 1.5)
    for i, (av, sh) in enumerate(lines):
        for j, hv in enumerate(hvs):
            r = rows.get((av, sh, hv))
            if r is None:
                continue
            lo, hi = r["av_first_pct_ci"]
            text = f"{r['av_first_pct']:.0f}%" + (f"\n[{lo:.0f}, {hi:.0f}]" if roomy else "")
            caused = r.get("collisions_caused_by_av", r["collisions"])
            if caused:
                text += f"\n{caused} coll." if roomy else f"\n\u00d7{caused}"
            dark = abs(r["av_first_pct"] - 50.0) > 30.0
            ax_m.text(j, i, text, ha="center", va="center", fontsize=size,
                      color="white" if dark else "black", gid=f"cell-{av}-{sh}-{hv}")
    ax_m.set_xticks(range(len(hvs)), hvs, fontsize=_FONT["tick"], rotation=30, ha="right")
    ax_m.set_yticks(range(len(lines)), names, fontsize=_FONT["tick"])
    ax_m.set_xlabel("human model", fontsize=_FONT["label"])
    ax_m.set_ylabel("AV planner", fontsize=_FONT["label"])
    ax_m.set_title("AV first at its line [% of runs]" if roomy else
                   "AV first at its line [% of runs];\n\u00d7N: N collisions caused by the AV",
                   fontsize=_FONT["title"])
    bar = fig.colorbar(image, ax=ax_m, fraction=0.05, pad=0.02)
    bar.ax.tick_params(labelsize=_FONT["tick"])

    labels, data, colors, notes, gids = [], [], [], [], []
    for (av, sh), name in zip(lines, names):
        for hv in hvs:
            mine = runs[(runs["av.kind"] == av) & (runs["hv.kind"] == hv)]
            if len(shields) > 1:
                mine = mine[mine["av.shield"] == sh]
            note = []
            for who, color in (("av", AV_COLOR), ("hv", HV_COLOR)):
                d = mine[f"{who}_delay_s"].to_numpy(dtype=float, na_value=np.nan)
                data.append(d[np.isfinite(d)])
                colors.append(color)
                note.append(_degenerate(who, data[-1]))
            labels.append(f"{av} ({sh}) / {hv}" if len(shields) > 1 else f"{av} / {hv}")
            gids.append(f"{av}-{sh}-{hv}" if len(shields) > 1 else f"{av}-{hv}")
            notes.append(", ".join(n for n in note if n))
    positions = np.arange(len(labels) * 2, dtype=float)
    positions += np.repeat(np.arange(len(labels)), 2) * 0.6  # a gap between pairs
    box = ax_b.boxplot([d if d.size else [np.nan] for d in data], positions=positions,
                       orientation="horizontal", widths=0.7, patch_artist=True,
                       showfliers=False,
                       medianprops={"color": "black", "lw": 0.8})
    for patch, color in zip(box["boxes"], colors):
        patch.set_facecolor(color)
        patch.set_alpha(0.6)
        patch.set_gid("delay-box")
    ax_b.set_yticks(positions[::2] + 0.5, labels, fontsize=_FONT["note"])
    ax_b.invert_yaxis()
    # A box of delays all zero is a bare tick, and no delay at all draws nothing: say so,
    # beside the tick when the pair has no other box, else at the right, in room kept free.
    finite = [d for d in data if d.size]
    lo = min([0.0, *(float(d.min()) for d in finite)])
    hi = max([0.0, *(float(d.max()) for d in finite)])
    span = hi - lo if hi > lo else 1.0
    alone = [not any(d.size and np.any(d != 0.0) for d in data[2 * i:2 * i + 2])
             for i in range(len(labels))]
    ax_b.set_xlim(lo - 0.03 * span, hi + (0.45 if not all(alone) else 0.05) * span)
    for i, (y, gid, note) in enumerate(zip(positions[::2] + 0.5, gids, notes)):
        if not note:
            continue
        where = dict(xy=(0.0, y), xytext=(4.0, 0.0), ha="left") if alone[i] else \
            dict(xy=(1.0, y), xytext=(-3.0, 0.0), ha="right",
                 xycoords=("axes fraction", "data"))
        ax_b.annotate(note, textcoords="offset points", va="center",
                      fontsize=_FONT["note"] - 0.5, color="0.2",
                      gid=f"delay-note-{gid}", **where)
    ax_b.set_xlabel("delay against free flow [s]", fontsize=_FONT["label"])
    ax_b.set_title("delays (AV red, human blue)", fontsize=_FONT["title"])
    _style(ax_b)
    fig.suptitle(f"compare: {summary['scenario']}, {summary['mode']} mode, seeds "
                 f"1..{summary['seeds']}", fontsize=_FONT["title"])
    return fig


def _degenerate(who: str, delays: np.ndarray) -> str:
    """What a pair's box of ``who``'s delays cannot show: ``"AV n/a"`` when that vehicle never
    cleared the conflict, ``"AV 0"`` when every delay is zero; else ``""``."""
    if delays.size == 0:
        return f"{who.upper()} n/a"
    if np.all(delays == 0.0):
        return f"{who.upper()} 0"
    return ""


__all__ = ["compare_figure"]
