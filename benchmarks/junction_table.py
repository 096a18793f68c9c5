"""The table of a junction sweep, one row per cell of its axes (docs/results.md §16.1, §16.3,
§16.4).

    python benchmarks/junction_table.py SWEEP_FOLDER [--liveness]

Reads the sweep's rows (``persuasive.sweep.load``; each is ``persuasive.many.world
.run_summary``'s row) and prints per combination of the axes: runs, AV through, AV first
through the conflicts both passed (and how many), AV-caused collisions, uncertified steps,
deadlocks (with the AV in them), human collisions, the mean delay caused [s] and the humans'
mean wait [s]. ``--liveness`` prints the liveness table instead (§16.4): AV through, AV first
through the conflicts both passed (the count, and the share of them), AV-caused collisions,
uncertified steps, deadlocks (with the AV in them; AV-caused: none of their humans deadlocked
without the AV), runs in which the AV stood inside the junction (while a human waited for
it), the AV's longest and 95th-percentile wait [s] and the mean delay caused [s].
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--liveness", action="store_true",
                        help="the liveness table (docs/results.md §16.4)")
    args = parser.parse_args()
    print(liveness_table(args.folder) if args.liveness else table(args.folder))


if __name__ == "__main__":
    main()
