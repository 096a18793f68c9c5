"""How fast the N-vehicle junction steps, and where the time goes, by number of vehicles.

    python benchmarks/junction_speed.py [--vehicles 2 3 4 6 8 10] [--seeds 50]
                                       [--plan pairwise joint] [--json]

For each N: ``--seeds`` runs (seeds 1..), one process, the default junction (``major``, one
lane, ``lfg`` humans playing their next conflict, the persuasive AV with the worst-case
shield, 30-s runs), timing every closed-loop step (every vehicle decides, all advance, every
conflict checked) and, inside it, the AV's decision (its planners and the shield) and the
humans' decisions. ``--plan``: how the AV plans (``junction.av_plan``: one planner per
human, or one plan against all; each plan is timed on the same seeds). Prints the medians and
99th percentiles [ms] and the share of the step each part takes. Targets (the 2-core
machine): one step at N = 10 at most 1 ms median (issue 40); the AV's decision with the
shield at N = 10 at most 1 ms median and 3 ms p99 (issue 41). The whole study's wall time is ``persuasive junction --vehicles 10 --seeds 500
--workers 2`` (at most 2 minutes).
"""

from __future__ import annotations

import argparse
import json

from persuasive.bench import bench_junction
from persuasive.config import Config


def measure(n: int, seeds: int, plan: str = "pairwise") -> dict:
    """One N's timings (``persuasive.bench.bench_junction``, as ``persuasive bench
    --scenario junction --vehicles N --runs SEEDS`` prints them for the pairwise plan)."""
    config = Config(mode="corrected").with_overrides({"scenario.kind": "junction",
                                                      "junction.n_vehicles": n,
                                                      "junction.av_plan": plan})
    return {**bench_junction(config, seeds), "plan": plan}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, nargs="+", default=[2, 3, 4, 6, 8, 10])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--plan", nargs="+", default=["pairwise"],
                        choices=["pairwise", "joint"])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [measure(n, args.seeds, plan) for n in args.vehicles for plan in args.plan]
    if args.json:
        print(json.dumps(rows))
        return
    print("| vehicles | AV plan | steps | step ms median / p99 | AV decision ms median / p99 "
          "| humans ms median | AV share | humans share |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['vehicles']} | {r['plan']} | {r['steps']} | {r['step_ms_median']:.3f} / "
              f"{r['step_ms_p99']:.3f} | {r['av_ms_median']:.3f} / {r['av_ms_p99']:.3f} "
              f"| {r['humans_ms_median']:.3f} | {100 * r['av_share']:.0f} % "
              f"| {100 * r['humans_share']:.0f} % |")


if __name__ == "__main__":
    main()
