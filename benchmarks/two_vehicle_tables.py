"""Two-vehicle runs read as the tables' N = 2 case: what the measures of many say of them,
beside the two-vehicle outcome, and what reading the tables costs.

    python benchmarks/two_vehicle_tables.py [--seeds 500] [--mode corrected] [--hv lfg]
                                           [--scenarios intersection crossing left-turn merge]

For each scenario: ``--seeds`` runs (seeds 0..), one process, the configured mode and human.
Per run, the outcome (``RunRecord.outcome``) and the measures of many
(``RunRecord.measures()``, ``persuasive.many.measures.summary`` on ``RunRecord.trace()``).
Prints per scenario: runs in which both vehicles passed the conflict point and those where
the AV was first by each (they must be equal: the test ``tests/test_tables.py`` pins it run by
run), AV-caused collisions by each, the two-vehicle standoffs (neither advances 0.5 m in 3 s)
and the wait-for deadlocks (a cycle held 5 s), how many runs have both, and the median time of
a run and of its trace plus measures [ms].
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from persuasive.config import Config
from persuasive.simulation import simulate


def measure(scenario: str, seeds: int, mode: str, hv: str) -> dict:
    config = Config(mode=mode).with_overrides({"scenario.kind": scenario, "hv.kind": hv})
    simulate(config, 0)  # load the kernels before the clock
    run_ms, tables_ms = [], []
    both = av_first_outcome = av_first_tables = caused_o = caused_t = 0
    standoff = deadlock = both_stuck = 0
    for seed in range(seeds):
        t0 = time.perf_counter()
        run = simulate(config, seed)
        t1 = time.perf_counter()
        m = run.measures()
        t2 = time.perf_counter()
        run_ms.append(1e3 * (t1 - t0))
        tables_ms.append(1e3 * (t2 - t1))
        o = run.outcome
        if m["av_conflicts_passed"]:
            both += 1
            av_first_tables += m["av_first_conflicts"]
            av_first_outcome += int(o.first_at_conflict_point == 1)
        caused_o += int(o.collision_caused_by_av)
        caused_t += m["av_caused_collisions"]
        standoff += int(o.deadlock)
        deadlock += int(m["deadlock"])
        both_stuck += int(o.deadlock and m["deadlock"])
    return {"scenario": scenario, "runs": seeds, "both_passed": both,
            "av_first_outcome": av_first_outcome, "av_first_tables": av_first_tables,
            "av_caused_outcome": caused_o, "av_caused_tables": caused_t,
            "standoffs": standoff, "wait_for_deadlocks": deadlock, "both_stuck": both_stuck,
            "run_ms_median": float(np.median(run_ms)),
            "tables_ms_median": float(np.median(tables_ms))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=500)
    ap.add_argument("--mode", default="corrected", choices=("paper", "corrected"))
    ap.add_argument("--hv", default="lfg")
    ap.add_argument("--scenarios", nargs="+",
                    default=["intersection", "crossing", "left-turn", "merge"])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = [measure(s, args.seeds, args.mode, args.hv) for s in args.scenarios]
    if args.json:
        print(json.dumps(rows))
        return
    print(f"{args.mode} mode, {args.hv} human, {args.seeds} seeds per scenario")
    print(f"{'scenario':<13}{'both':>6}{'first o/t':>11}{'caused o/t':>12}{'standoff':>10}"
          f"{'deadlock':>10}{'both':>6}{'run ms':>9}{'tables ms':>11}")
    for r in rows:
        print(f"{r['scenario']:<13}{r['both_passed']:>6}"
              f"{r['av_first_outcome']:>6}/{r['av_first_tables']:<4}"
              f"{r['av_caused_outcome']:>7}/{r['av_caused_tables']:<4}"
              f"{r['standoffs']:>10}{r['wait_for_deadlocks']:>10}{r['both_stuck']:>6}"
              f"{r['run_ms_median']:>9.2f}{r['tables_ms_median']:>11.2f}")


if __name__ == "__main__":
    main()
