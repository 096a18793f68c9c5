"""What the shield costs the planner, and what knowing it buys (issue 25 item 6; SHARP's measure).

    python benchmarks/shield_cost.py [--scenarios intersection,merge] [--hv lfg,idm,...]
                                     [--seeds 200] [--steps 200] [--workers N]

For each scenario runs ``persuasive compare`` (corrected mode, the persuasive planner, seeds
1..N, ``simulation.n_steps = --steps``) three times on the same seeds: without a shield, behind
the worst-case shield with a planner that does not know it (``mpc.shield_aware = false``: its
proposals are filtered after the fact, a shield-agnostic planner), and behind it with the
planner that plans inside what it admits (``mpc.shield_aware = true``, the default). Prints one
row per (scenario, human, setting): the share of the AV's steps the shield overrode and the mean
change it made to the proposal, both vehicles through, the AV first through the conflict point,
the AV's time to clear as a restricted mean over all runs, standoffs, AV-caused collisions.
SHARP (Hu, Nakamura, Fisac, RA-L 2022) compares a shielding-aware planner with a
shielding-agnostic one behind the same shield; the last column gives the aware planner's gain in
the AV's time to clear over the agnostic one, in percent of the agnostic one's.
"""

from __future__ import annotations

import argparse
import tempfile

from persuasive.config import Config
from persuasive.studies.compare import parse_kinds, run_comparison

HUMANS = ("lfg", "noisy", "idm", "stubborn", "aggressive")
SETTINGS = (("no shield", {"av.shield": "off"}),
            ("shield, agnostic planner", {"av.shield": "worst-case", "mpc.shield_aware": False}),
            ("shield, aware planner", {"av.shield": "worst-case", "mpc.shield_aware": True}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="intersection,merge")
    parser.add_argument("--hv", default=",".join(HUMANS))
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    humans = parse_kinds(args.hv, HUMANS + ("adversary", "deceptive", "random"), "--hv", HUMANS)
    print(f"corrected mode, persuasive AV, seeds 1..{args.seeds}, {args.steps} steps")
    print("| scenario | human | setting | overrides % of steps | mean change m/s^2 | "
          "both through % | AV first through % | AV clear s (restricted mean) | standoffs | "
          "AV-caused | aware's gain over agnostic % |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for scenario in args.scenarios.split(","):
        rows: dict[str, dict[str, dict]] = {}
        for name, over in SETTINGS:
            base = Config(mode="corrected").with_overrides({
                "scenario.kind": scenario, "simulation.n_steps": args.steps, **over})
            with tempfile.TemporaryDirectory() as tmp:
                summary = run_comparison(base, ("persuasive",), humans, args.seeds,
                                         out=f"{tmp}/compare", workers=args.workers,
                                         timing_seeds=1).summary
            rows[name] = {r["hv"]: r for r in summary["rows"]}
        for hv in humans:
            agnostic = rows[SETTINGS[1][0]][hv]["av_clear_s_rmean"]
            for name, _ in SETTINGS:
                r = rows[name][hv]
                gain = ""
                if name == SETTINGS[2][0] and agnostic:
                    gain = f"{100.0 * (agnostic - r['av_clear_s_rmean']) / agnostic:+.1f}"
                print(f"| {scenario} | {hv} | {name} | {r['override_pct']:.1f} | "
                      f"{r['override_mps2_mean']:.3f} | {r['both_cleared_pct']:.1f} | "
                      f"{r['av_first_through_pct']:.1f} | {r['av_clear_s_rmean']:.2f} | "
                      f"{r['deadlocks']} | {r['collisions_caused_by_av']} | {gain} |",
                      flush=True)


if __name__ == "__main__":
    main()
