"""What the junction's foresight costs: a whole run (built and run, no reference) with each
way of placing the AV's yield lines (docs/method.md §15.9, results §16.4).

    python benchmarks/junction_foresight_cost.py [--vehicles 3 6 10] [--seeds 10] [--rounds 2]

For each N: seeds 1..``--seeds`` of the default junction (``lfg`` humans, the persuasive AV,
worst-case shield, 30-s runs), one process, each line placement timed over the same seeds in
alternating rounds; prints the mean time of a run in the fastest round [s] and foresight's
ratio to ``outside``.
"""

from __future__ import annotations

import argparse
import time

from persuasive.config import Config
from persuasive.many.world import JunctionWorld

LINES = ("outside", "stop", "foresight")


def run_time(n: int, line: str, seeds: int) -> float:
    """The mean time of one run [s] over seeds 1..``seeds``."""
    config = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                      "junction.n_vehicles": n,
                                                      "junction.av_line": line})
    t0 = time.perf_counter()
    for seed in range(1, seeds + 1):
        JunctionWorld.of(config, seed).run()
    return (time.perf_counter() - t0) / seeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, nargs="+", default=[3, 6, 10])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    JunctionWorld.of(Config(mode="corrected").with_overrides(
        {"scenario.kind": "junction", "junction.av_line": "foresight"}), 0)  # compile/load
    print("| vehicles | " + " | ".join(f"{line} [s]" for line in LINES) +
          " | foresight / outside |")
    print("|---|" + "---|" * (len(LINES) + 1))
    for n in args.vehicles:
        times: dict[str, list[float]] = {line: [] for line in LINES}
        for _ in range(args.rounds):  # alternating: every line once a round
            for line in LINES:
                times[line].append(run_time(n, line, args.seeds))
        best = {line: min(t) for line, t in times.items()}
        print(f"| {n} | " + " | ".join(f"{best[line]:.3f}" for line in LINES) +
              f" | {best['foresight'] / best['outside']:.1f} |")


if __name__ == "__main__":
    main()
