"""The table of a junction sweep, one row per cell of its axes (docs/results.md §16.1, §16.3,
§16.4, §16.5).

    python benchmarks/junction_table.py SWEEP_FOLDER [--liveness | --study |
                                                     --paired AXIS=VALUE |
                                                     --versus OTHER [--where AXIS=VALUE]]

Reads the sweep's rows (``persuasive.sweep.load``; each is ``persuasive.many.world
.run_summary``'s row) and prints per combination of the axes: runs, AV through, AV first
through the conflicts both passed (and how many), AV-caused collisions, uncertified steps,
deadlocks (with the AV in them), human collisions, the mean delay caused [s] and the humans'
mean wait [s]. ``--liveness`` prints the liveness table instead (§16.4): AV through, AV first
through the conflicts both passed (the count, and the share of them), AV-caused collisions,
uncertified steps, deadlocks (with the AV in them; AV-caused: none of their humans deadlocked
without the AV), runs in which the AV stood inside the junction (while a human waited for
it), the AV's longest and 95th-percentile wait [s] and the mean delay caused [s]. ``--study``
prints the study's table (§16.5, :func:`study_table`), ``--paired av.kind=persuasive`` each
AV kind against the persuasive one, paired by seed (:func:`paired_table`); ``--versus OTHER
--where av.kind=persuasive`` the persuasive runs against another sweep's, paired by seed
(:func:`versus_table`).
"""

from __future__ import annotations

import argparse

import numpy as np

from persuasive.sweep import load
from persuasive.sweep.store import read_manifest


def _cells(folder: str, columns: str):
    """The table's two header lines (the sweep's axes, then ``columns``, ``|``-separated) and
    each cell of the axes: ``(its values, its rows, AV first, conflicts both passed)``."""
    axes = list(read_manifest(folder)["axes"])
    head = [f"| {' | '.join(axes)} | {columns} |",
            "|" + "---|" * (len(axes) + columns.count("|") + 1)]
    cells = []
    for key, g in load(folder).groupby(axes, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        cells.append((" | ".join(str(k) for k in key), g, int(g["av_first_conflicts"].sum()),
                      int(g["av_conflicts_passed"].sum())))
    return head, cells


def table(folder: str) -> str:
    lines, cells = _cells(folder, "runs | AV through | AV first (conflicts) | AV-caused "
                          "collisions | uncertified steps | deadlocks (AV in) | human "
                          "collisions | delay caused [s] | humans' mean wait [s]")
    for key, g, first, both in cells:
        share = f"{100 * first / both:.1f} % ({both})" if both else "- (0)"
        lines.append(
            f"| {key} | {len(g)} | {100 * g['av_through'].mean():.1f} % | {share} | "
            f"{int(g['av_caused_collisions'].sum())} | {int(g['uncertified_steps'].sum())} | "
            f"{int(g['deadlock'].sum())} ({int(g['av_in_deadlock'].sum())}) | "
            f"{int(g['human_collisions'].sum())} | {g['caused_delay_s'].mean():.2f} | "
            f"{g['mean_wait_s'].mean():.2f} |")
    return "\n".join(lines)


def liveness_table(folder: str) -> str:
    lines, cells = _cells(folder, "runs | AV through | AV first (of conflicts) | AV-caused "
                          "collisions | uncertified steps | deadlocks (AV in, AV-caused) | AV "
                          "stood inside (a human waiting) | AV wait max / p95 [s] | delay "
                          "caused [s]")
    for key, g, first, both in cells:
        share = f"{first} ({100 * first / both:.1f} % of {both})" if both else "0 (of 0)"
        wait = g["av_wait_s"].to_numpy(float)
        lines.append(
            f"| {key} | {len(g)} | {100 * g['av_through'].mean():.1f} % | {share} | "
            f"{int(g['av_caused_collisions'].sum())} | {int(g['uncertified_steps'].sum())} | "
            f"{int(g['deadlock'].sum())} ({int(g['av_in_deadlock'].sum())}, "
            f"{int(g['av_caused_deadlock'].sum())}) | "
            f"{int((g['av_inside_stood_s'] > 0).sum())} "
            f"({int((g['av_inside_blocking_s'] > 0).sum())}) | "
            f"{wait.max():.1f} / {np.percentile(wait, 95):.1f} | "
            f"{g['caused_delay_s'].mean():.2f} |")
    return "\n".join(lines)


def study_table(folder: str) -> str:
    """The study's table (docs/results.md §16.5): per cell, AV through within the run, AV
    first through the conflicts both passed, AV-caused collisions, uncertified steps, runs
    with a deadlock (the AV's own), the AV's mean delay, the mean delay it causes, the mean
    throughput, the AV's lowest PET (5th percentile over the runs with one) and the shield's
    overrides per run."""
    lines, cells = _cells(folder, "runs | AV through | AV first (of conflicts) | AV-caused "
                          "collisions | uncertified steps | deadlocks (AV-caused) | AV delay "
                          "[s] | delay caused [s] | throughput [veh/h] | AV min PET p5 [s] | "
                          "overrides / run")
    for key, g, first, both in cells:
        share = f"{100 * first / both:.1f} % ({both})" if both else "- (0)"
        pet = g["min_pet_av_s"].to_numpy(float)
        pet = pet[np.isfinite(pet)]
        delay = g.loc[g["av_through"], "av_delay_s"]
        lines.append(
            f"| {key} | {len(g)} | {100 * g['av_through'].mean():.1f} % | {share} | "
            f"{int(g['av_caused_collisions'].sum())} | {int(g['uncertified_steps'].sum())} | "
            f"{int(g['deadlock'].sum())} ({int(g['av_caused_deadlock'].sum())}) | "
            f"{delay.mean():.2f} | {g['caused_delay_s'].mean():.2f} | "
            f"{g['throughput_veh_h'].mean():.0f} | "
            f"{np.percentile(pet, 5) if pet.size else float('nan'):.2f} | "
            f"{g['shield_overrides'].mean():.1f} |")
    return "\n".join(lines)


def interval(d: np.ndarray, scale: float) -> str:
    """Mean and normal 95 % interval of paired differences ``d``, times ``scale`` (100:
    points, one decimal; 1: seconds, two)."""
    half = 1.959963984540054 * d.std(ddof=1) / np.sqrt(d.size) if d.size > 1 else np.nan
    digits = 1 if scale == 100 else 2
    return f"{scale * d.mean():+.{digits}f} [{scale * (d.mean() - half):+.{digits}f}, " \
           f"{scale * (d.mean() + half):+.{digits}f}]"


def _paired(runs, ref) -> str:
    """``runs | AV through | delay caused`` cells of ``runs`` against ``ref`` (both indexed by
    seed), over the seeds both ran: how many, and the paired differences' :func:`interval`."""
    seeds = ref.index.intersection(runs.index)
    runs, ref = runs.loc[seeds], ref.loc[seeds]
    through = runs["av_through"].to_numpy(float) - ref["av_through"].to_numpy(float)
    delay = runs["caused_delay_s"].to_numpy(float) - ref["caused_delay_s"].to_numpy(float)
    return f"{len(seeds)} | {interval(through, 100)} | {interval(delay, 1)}"


def versus_table(folder: str, other: str, where: str | None) -> str:
    """The runs of ``folder`` (those with ``where``, ``AXIS=VALUE``, if given) against those of
    another sweep ``other``, paired by seed within every combination of ``other``'s axes
    (which ``folder`` must have too): the difference (``folder`` minus ``other``) in AV
    through [points] and in the delay caused [s], as :func:`paired_table`'s."""
    frame, base = load(folder), load(other)
    if where:
        axis, value = where.split("=", 1)
        if axis not in frame:
            raise SystemExit(f"error: --where {axis!r} is not a column of {folder!r}")
        frame = frame[frame[axis].astype(str) == value]
    axes = list(read_manifest(other)["axes"])
    missing = [a for a in axes if a not in frame]
    if missing:
        raise SystemExit(f"error: --versus {other!r} has axes {folder!r} lacks: "
                         f"{', '.join(missing)}")
    lines = [f"| {' | '.join(axes)} | runs | AV through [points] | delay caused [s] |",
             "|" + "---|" * (len(axes) + 3)]
    for key, g in frame.groupby(axes, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        ref = base
        for a, k in zip(axes, key):
            ref = ref[ref[a] == k]
        lines.append(f"| {' | '.join(str(k) for k in key)} | "
                     f"{_paired(g.set_index('seed'), ref.set_index('seed'))} |")
    return "\n".join(lines)


def paired_table(folder: str, against: str) -> str:
    """Each value of one axis against one of them, paired by seed within every combination
    of the other axes (``against``: ``AXIS=VALUE``, e.g. ``av.kind=persuasive``): the
    difference (other minus it) in AV through [points] and in the delay caused [s], mean and
    95 % interval (normal approximation over the seeds' paired differences)."""
    axis, base = against.split("=", 1)
    frame = load(folder)
    axes = list(read_manifest(folder)["axes"])
    if axis not in axes:
        raise SystemExit(f"error: --paired {axis!r} is not an axis of the sweep; allowed: "
                         f"{', '.join(axes)}")
    others = [a for a in axes if a != axis]
    lines = [f"| {' | '.join(others)} | {axis} | runs | AV through [points] | delay caused "
             "[s] |", "|" + "---|" * (len(others) + 4)]
    for key, g in frame.groupby(others, sort=True) if others else [((), frame)]:
        key = key if isinstance(key, tuple) else (key,)
        ref = g[g[axis].astype(str) == base].set_index("seed")
        if ref.empty:
            raise SystemExit(f"error: --paired {axis}={base!r} has no runs; allowed: "
                             f"{', '.join(map(str, g[axis].unique()))}")
        for value, h in g.groupby(axis, sort=False):
            if str(value) == base:
                continue
            lines.append(f"| {' | '.join(str(k) for k in key)} | {value} | "
                         f"{_paired(h.set_index('seed'), ref)} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    kind = parser.add_mutually_exclusive_group()
    kind.add_argument("--liveness", action="store_true",
                      help="the liveness table (docs/results.md §16.4)")
    kind.add_argument("--study", action="store_true",
                      help="the study's table (docs/results.md §16.5)")
    kind.add_argument("--paired", metavar="AXIS=VALUE",
                      help="every value of AXIS against VALUE, paired by seed (e.g. "
                           "av.kind=persuasive)")
    kind.add_argument("--versus", metavar="OTHER_SWEEP",
                      help="the runs against another sweep's, paired by seed within its axes "
                           "(with --where AXIS=VALUE to keep some runs)")
    parser.add_argument("--where", metavar="AXIS=VALUE", default=None)
    args = parser.parse_args()
    print(liveness_table(args.folder) if args.liveness else
          study_table(args.folder) if args.study else
          paired_table(args.folder, args.paired) if args.paired else
          versus_table(args.folder, args.versus, args.where) if args.versus else
          table(args.folder))


if __name__ == "__main__":
    main()
