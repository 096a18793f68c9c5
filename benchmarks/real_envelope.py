"""The shields under the real drivers' envelope, beside the paper's, in our simulator (issue
42 item 5, docs/method.md §12.2).

    python benchmarks/real_envelope.py [--seeds 300] [--steps 200]
                                       [--envelopes paper,real-driver]
                                       [--shields worst-case,responsibility]
                                       [--scenarios intersection,crossing,left-turn,merge]
                                       [--hv lfg,noisy,idm,stubborn,aggressive] [--workers N]

For each human envelope (``hv.envelope``: ``paper`` is the configuration's own limits,
``[-2, 1]`` m/s^2 up to 10 m/s; ``real-driver`` is ``[-3.7, 3.5]`` up to 16.5 m/s), each shield
and each scenario it runs ``persuasive compare`` in corrected mode with its defaults otherwise
(the persuasive planner, foresight over [0, 3.75, 8] m, the clearance) against each human on
seeds 1..N, runs of ``--steps`` steps (200: 20 s). The envelope is both what the simulated
human can do (its library and its limits) and what the shield assumes of it. One row per
(envelope, shield, scenario, human): both vehicles through, standoffs, the AV first through
(with its 95 % interval), AV-caused collisions, uncertified steps, the mean time the human
lost (its delay: time to clear less its free-flow time) and the AV's.
"""

from __future__ import annotations

import argparse
import tempfile
import time

from persuasive.config import HUMAN_ENVELOPES, Config
from persuasive.studies.compare import parse_kinds, run_comparison

HUMANS = ("lfg", "noisy", "idm", "stubborn", "aggressive")
SCENARIOS = ("intersection", "crossing", "left-turn", "merge")
SHIELDS = ("worst-case", "responsibility")


def rows_of(base: Config, humans, seeds: int, workers: int | None) -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        return run_comparison(base, ("persuasive",), humans, seeds, out=f"{tmp}/compare",
                              workers=workers, timing_seeds=1).summary["rows"]


def _mean(x) -> str:
    return "-" if x is None else f"{x:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=300)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--envelopes", default="paper,real-driver")
    parser.add_argument("--shields", default=",".join(SHIELDS))
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--hv", default=",".join(HUMANS))
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    humans = parse_kinds(args.hv, HUMANS + ("adversary", "deceptive", "random"), "--hv", HUMANS)
    envelopes = [e for e in args.envelopes.split(",") if e]
    for e in envelopes:
        if e != "paper" and e not in HUMAN_ENVELOPES:
            parser.error(f"--envelopes: {e!r} is not an envelope; allowed: paper, "
                         + ", ".join(HUMAN_ENVELOPES))
    print(f"corrected mode, persuasive AV, seeds 1..{args.seeds}, {args.steps} steps")
    print("| envelope | shield | scenario | human | both through % | standoffs | AV first "
          "through % [95 % CI] | AV-caused | uncertified | human delay s | AV delay s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    for envelope in envelopes:
        for shield in [s for s in args.shields.split(",") if s]:
            for scenario in [s for s in args.scenarios.split(",") if s]:
                over = {"scenario.kind": scenario, "simulation.n_steps": args.steps,
                        "av.shield": shield}
                if envelope != "paper":
                    over["hv.envelope"] = envelope
                base = Config(mode="corrected").with_overrides(over)
                for r in rows_of(base, humans, args.seeds, args.workers):
                    lo, hi = r["av_first_through_pct_ci"]
                    print(f"| {envelope} | {shield} | {scenario} | {r['hv']} | "
                          f"{r['both_cleared_pct']:.1f} | {r['deadlocks']} | "
                          f"{r['av_first_through_pct']:.1f} [{lo:.1f}, {hi:.1f}] | "
                          f"{r['collisions_caused_by_av']} | {r['uncertified_steps']} | "
                          f"{_mean(r['hv_delay_s_mean'])} | {_mean(r['av_delay_s_mean'])} |",
                          flush=True)
    print(f"wall time: {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
