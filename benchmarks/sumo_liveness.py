"""The shielded planner against SUMO's own driver, paired by seed (docs/method.md §12.8, §14).

    python benchmarks/sumo_liveness.py [--episodes 100] [--flows 300,900]
                                       [--ignore-foes 0,0.3] [--scenarios intersection,merge]

For every (scenario, flow, share of reckless drivers) runs ``--episodes`` seeds from 1 with the
persuasive planner behind the worst-case shield and with SUMO's own driver as the ego (each
after the run without an ego, the time-loss reference), and prints one row per configuration:
episodes crossed or merged within 60 s by each, the paired difference (planner minus SUMO, in
points, with a 95 % bootstrap interval over seeds), the time loss each caused per episode
(mean), the time the ego stood inside the junction, SUMO's vehicles it forced to brake (harder
than 1.5 m/s^2, counted against the same seed without the ego; mean per episode), collisions
and uncertified steps; then SUMO's own driver judged by the worst-case shield it does not use:
of its entries into the junction (or the merge), how many the certificate would have admitted
as driven, and the share of all its steps it would have admitted (a ceiling on what a planner
behind that shield could copy of SUMO's driving, issue 25).
"""

from __future__ import annotations

import argparse
import shutil

import numpy as np

from persuasive.envs.sumo import SUMO_DRIVER, run_study


def paired_ci(diff: np.ndarray, seed: int = 12345, n: int = 4000) -> tuple[float, float]:
    """95 % percentile bootstrap interval of the mean of ``diff`` (resampling seeds)."""
    rng = np.random.default_rng(seed)
    means = rng.choice(diff, size=(n, diff.size), replace=True).mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--flows", default="300,900")
    parser.add_argument("--ignore-foes", default="0,0.3")
    parser.add_argument("--scenarios", default="intersection,merge")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    print(f"seeds 1..{args.episodes}; planner: persuasive + worst-case shield; SUMO: its own "
          "driver as the ego")
    print("| scenario | flow veh/h | reckless | crossed: planner / SUMO | difference points "
          "[95 % CI] | time loss caused s: planner / SUMO | stood in junction s: planner / "
          "SUMO | forced to brake: planner / SUMO | collisions | uncertified | SUMO's entries the "
          "shield admits | SUMO's steps it admits % |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for scenario in args.scenarios.split(","):
        for flow in (float(x) for x in args.flows.split(",")):
            for foes in (float(x) for x in args.ignore_foes.split(",")):
                report, _, folder = run_study(scenario, args.episodes, 1, flow, foes,
                                              workers=args.workers)
                if folder is not None:
                    shutil.rmtree(folder, ignore_errors=True)
                eps = {d: sorted((e for e in report.episodes if e.driver == d),
                                 key=lambda e: e.seed) for d in report.drivers}
                mine = eps[next(d for d in report.drivers if d != SUMO_DRIVER)]
                ref = eps[SUMO_DRIVER]
                diff = 100.0 * (np.array([e.crossed for e in mine], float)
                                - np.array([e.crossed for e in ref], float))
                lo, hi = paired_ci(diff)

                def loss(es):
                    return np.mean([e.caused_time_loss_s or 0.0 for e in es])

                def forced(es):
                    return np.mean([e.forced_to_brake or 0 for e in es])

                def admitted_pct(es):
                    steps = sum(e.judged_steps for e in es)
                    return 100.0 * sum(e.judged_admitted for e in es) / max(1, steps)

                print(f"| {scenario} | {flow:g} | {foes:g} | {sum(e.crossed for e in mine)} / "
                      f"{sum(e.crossed for e in ref)} | {diff.mean():+.1f} [{lo:+.1f}, {hi:+.1f}]"
                      f" | {loss(mine):.2f} / {loss(ref):.2f} | "
                      f"{sum(e.junction_stood_s for e in mine):.1f} / "
                      f"{sum(e.junction_stood_s for e in ref):.1f} | "
                      f"{forced(mine):.2f} / {forced(ref):.2f} | "
                      f"{sum(e.collisions for e in mine)} / {sum(e.collisions for e in ref)} | "
                      f"{sum(e.uncertified for e in mine)} | "
                      f"{sum(bool(e.entry_admitted) for e in ref)} of "
                      f"{sum(e.entry_admitted is not None for e in ref)} | "
                      f"{admitted_pct(ref):.1f} |", flush=True)


if __name__ == "__main__":
    main()
