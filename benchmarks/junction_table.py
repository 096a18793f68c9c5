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


def table(folder: str) -> str:
    axes = list(read_manifest(folder)["axes"])
    rows = load(folder)
    lines = [f"| {' | '.join(axes)} | runs | AV through | AV first (conflicts) | AV-caused "
             "collisions | uncertified steps | deadlocks (AV in) | human collisions | delay "
             "caused [s] | humans' mean wait [s] |",
             "|" + "---|" * (len(axes) + 9)]
    for key, g in rows.groupby(axes, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        both = int(g["av_conflicts_passed"].sum())
        first = int(g["av_first_conflicts"].sum())
        share = f"{100 * first / both:.1f} % ({both})" if both else "- (0)"
        lines.append(
            f"| {' | '.join(str(k) for k in key)} | {len(g)} | "
            f"{100 * g['av_through'].mean():.1f} % | {share} | "
            f"{int(g['av_caused_collisions'].sum())} | {int(g['uncertified_steps'].sum())} | "
            f"{int(g['deadlock'].sum())} ({int(g['av_in_deadlock'].sum())}) | "
            f"{int(g['human_collisions'].sum())} | {g['caused_delay_s'].mean():.2f} | "
            f"{g['mean_wait_s'].mean():.2f} |")
    return "\n".join(lines)


def liveness_table(folder: str) -> str:
    axes = list(read_manifest(folder)["axes"])
    rows = load(folder)
    lines = [f"| {' | '.join(axes)} | runs | AV through | AV first (of conflicts) | AV-caused "
             "collisions | uncertified steps | deadlocks (AV in, AV-caused) | AV stood inside "
             "(a human waiting) | AV wait max / p95 [s] | delay caused [s] |",
             "|" + "---|" * (len(axes) + 9)]
    for key, g in rows.groupby(axes, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        both = int(g["av_conflicts_passed"].sum())
        first = int(g["av_first_conflicts"].sum())
        share = f"{first} ({100 * first / both:.1f} % of {both})" if both else "0 (of 0)"
        wait = g["av_wait_s"].to_numpy(float)
        lines.append(
            f"| {' | '.join(str(k) for k in key)} | {len(g)} | "
            f"{100 * g['av_through'].mean():.1f} % | {share} | "
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
