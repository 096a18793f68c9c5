"""The table of a junction sweep, one row per cell of its axes (docs/results.md §16.1, §16.3).

    python benchmarks/junction_table.py SWEEP_FOLDER

Reads the sweep's rows (``persuasive.sweep.load``; each is ``persuasive.many.world
.run_summary``'s row) and prints per combination of the axes: runs, AV through, AV first
through the conflicts both passed (and how many), AV-caused collisions, uncertified steps,
deadlocks (with the AV in them), human collisions, the mean delay caused [s] and the humans'
mean wait [s].
"""

from __future__ import annotations

import argparse

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    print(table(parser.parse_args().folder))


if __name__ == "__main__":
    main()
