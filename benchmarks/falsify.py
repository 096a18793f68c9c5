"""The falsifier against the shield: the closest a steered bounded human gets (docs/method.md §12.2).

    python benchmarks/falsify.py [--rounds 5] [--samples 30] [--margins 0,0.2] [--seeds 1]

For the intersection, a 50-degree crossing, the left turn and the merge, runs
``persuasive.safety.falsifier.falsify`` (a cross-entropy search over piecewise-constant human
accelerations, ``--samples x --rounds`` runs each) against the persuasive planner without a
shield and with the worst-case shield at each clearance of ``--margins``, from the initial
states of seeds 1..``--seeds``, and prints the smallest footprint gap found per row (0: a human
touched the AV; rear-ends by the human in the merge left out).
"""

from __future__ import annotations

import argparse

from persuasive.config import Config
from persuasive.safety.falsifier import falsify

SCENARIOS = {"intersection": {}, "crossing at 50 degrees": {"scenario.kind": "crossing",
                                                            "scenario.angle_deg": 50.0},
             "left turn": {"scenario.kind": "left-turn"}, "merge": {"scenario.kind": "merge"}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--samples", type=int, default=30)
    parser.add_argument("--margins", default="0,0.2")
    parser.add_argument("--seeds", type=int, default=1)
    args = parser.parse_args()
    margins = [float(m) for m in args.margins.split(",")]
    print(f"{args.samples} x {args.rounds} runs per search, 61 steps, the persuasive planner")
    print("| scenario | seed | no shield | " + " | ".join(
        f"worst-case, clearance {m:g} m" for m in margins) + " |")
    print("|---|---|---|" + "---|" * len(margins))
    for name, over in SCENARIOS.items():
        base = Config(mode="corrected").with_overrides({**over, "simulation.n_steps": 61})
        for seed in range(1, args.seeds + 1):
            cells = [falsify(base.with_overrides({"av.shield": "off"}), samples=args.samples,
                             rounds=args.rounds, run_seed=seed)]
            cells += [falsify(base.with_overrides({"av.shield_margin_m": m}),
                              samples=args.samples, rounds=args.rounds, run_seed=seed)
                      for m in margins]
            print(f"| {name} | {seed} | " + " | ".join(
                f"{c:.4f}" if c == 0.0 or c >= 1e-3 else f"{c:.1e}" for c in cells) + " |",
                flush=True)


if __name__ == "__main__":
    main()
