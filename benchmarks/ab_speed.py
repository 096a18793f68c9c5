"""Speed of two source trees in one run: ``persuasive bench`` alternately in each, N times.

    python benchmarks/ab_speed.py OLD_SRC NEW_SRC [--rounds 5] [--runs 10]

OLD_SRC and NEW_SRC are ``src`` folders (e.g. a ``git worktree`` of the previous commit and
this checkout's ``src``); each round runs the benchmark once in a fresh process for each tree,
in alternating order, so that both see the same machine load. Prints, per figure, the median
over the rounds of each tree and the ratio new / old. Run it on an idle machine; the kernels
of each tree are compiled (and cached) on the first round.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

FIGURES = ("game_solve_us_median", "mpc_decision_ms_median", "mpc_decision_ms_p99",
           "mpc_run_ms_median", "shield_us_median", "shielded_decision_ms_median",
           "merge_geometry_ms_median")

SNIPPET = """
import json, statistics, sys, time
from persuasive.bench import bench
r = bench(n_runs={runs}, repeats=3)
# the merge's geometry, uncached (a recording's merge view builds one per view): both
# occupancy intervals and the AV's zone, as persuasive.scenarios.merge.build calls them
from persuasive import geometry as G
from persuasive.config import Config
from persuasive.scenarios import build_scenario
from persuasive.scenarios.base import pair_min_dist
config = Config().with_overrides({{"scenario.kind": "merge"}})
sc = build_scenario(config)
times = []
for _ in range(5):
    t = time.perf_counter()
    lo = G.occupancy_interval.__wrapped__(sc.av, sc.hv)[0]
    G.occupancy_interval.__wrapped__(sc.hv, sc.av, (lo, 0.0))
    G.zone_interval.__wrapped__(sc.av, sc.hv, pair_min_dist(config))
    times.append(1e3 * (time.perf_counter() - t))
r["merge_geometry_ms_median"] = statistics.median(times)
print(json.dumps({{k: r[k] for k in {figures!r} if k in r}}))
"""


def run(src: str, runs: int) -> dict:
    # the tree first; what PYTHONPATH already holds (e.g. installed wheels) after it
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (os.path.abspath(src), os.environ.get("PYTHONPATH", "")) if p))
    out = subprocess.run([sys.executable, "-c", SNIPPET.format(runs=runs, figures=FIGURES)],
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old_src")
    parser.add_argument("new_src")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--runs", type=int, default=10)
    args = parser.parse_args()
    run(args.old_src, 1), run(args.new_src, 1)  # compile and cache both
    results = {"old": [], "new": []}
    for i in range(args.rounds):
        order = ("old", "new") if i % 2 == 0 else ("new", "old")
        for name in order:
            results[name].append(run(getattr(args, f"{name}_src"), args.runs))
    print(f"{'figure':28} {'old':>10} {'new':>10} {'new/old':>8}   ({args.rounds} rounds, medians)")
    summary = {}
    for fig in FIGURES:
        if not all(fig in r for r in results["old"] + results["new"]):
            continue  # a figure one of the trees does not measure
        old = statistics.median(r[fig] for r in results["old"])
        new = statistics.median(r[fig] for r in results["new"])
        summary[fig] = {"old": old, "new": new, "ratio": new / old}
        print(f"{fig:28} {old:10.4f} {new:10.4f} {new / old:8.3f}")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
