"""Corrected mode's defaults, measured: foresight's lines and the shield's clearance (issue 39,
docs/method.md §12.14).

    python benchmarks/defaults.py [--margins 0,0.1,0.2,0.3] [--seeds 200] [--steps 200]
                                  [--scenarios intersection,crossing,left-turn,merge]
                                  [--hv lfg,noisy,idm,stubborn,aggressive] [--ablation]

For each clearance ``av.shield_margin_m`` of ``--margins`` and each scenario runs ``persuasive
compare`` in corrected mode with its defaults otherwise (the worst-case shield, the persuasive
planner, foresight over [0, 3.75, 8] m) against each human on seeds 1..N, runs of ``--steps``
steps (200: 20 s), and prints one row per (clearance, scenario, human): both vehicles through,
standoffs, the AV first through the conflict point (with its 95 % interval), AV-caused
collisions, uncertified steps and the closest the footprints came (runs with a rear-end by the
human left out). ``--ablation`` adds the rows of the named ablation, corrected mode as it
shipped before these defaults (the line at the interval, no clearance:
``persuasive.config.LINE_AT_INTERVAL``).

Then it applies the stated criterion and names the clearance it picks: **the largest clearance
of ``--margins`` with which every cell keeps at least 99 % of runs with both vehicles through,
no standoff, no AV-caused collision, no uncertified step and the footprints at least the
clearance apart, and with which the AV goes first through against the paper's human (``lfg``)
no more than 2 points less often than with no clearance, in every scenario.** The clearance
is the shield's real distance between the footprints (docs/method.md §12.2): with errors in
the positions it is not told of, up to ``e`` on each vehicle, the true footprints keep
``clearance - 2 e`` apart, so a clearance of ``c`` survives errors up to ``c / 2`` per
vehicle.
"""

from __future__ import annotations

import argparse
import tempfile
import time

from persuasive.config import LINE_AT_INTERVAL, Config
from persuasive.studies.compare import parse_kinds, run_comparison

HUMANS = ("lfg", "noisy", "idm", "stubborn", "aggressive")
SCENARIOS = ("intersection", "crossing", "left-turn", "merge")
#: the criterion's bounds (module docstring)
BOTH_MIN_PCT, PERSUASION_LOSS_MAX_PTS = 99.0, 2.0


def rows_of(base: Config, humans, seeds: int, workers: int | None) -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        return run_comparison(base, ("persuasive",), humans, seeds, out=f"{tmp}/compare",
                              workers=workers, timing_seeds=1).summary["rows"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--margins", default="0,0.1,0.2,0.3")
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--hv", default=",".join(HUMANS))
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--ablation", action="store_true")
    args = parser.parse_args()
    humans = parse_kinds(args.hv, HUMANS + ("adversary", "deceptive", "random"), "--hv", HUMANS)
    scenarios = [s for s in args.scenarios.split(",") if s]
    margins = [float(x) for x in args.margins.split(",")]
    print(f"corrected mode, worst-case shield, persuasive AV, seeds 1..{args.seeds}, "
          f"{args.steps} steps; foresight over its default lines unless the row says the "
          "ablation")
    print("| setting | scenario | human | both through % | standoffs | AV first through % "
          "[95 % CI] | AV-caused | uncertified | min gap m |")
    print("|---|---|---|---|---|---|---|---|---|")
    settings = [(f"clearance {m:g} m", {"av.shield_margin_m": m}) for m in margins]
    if args.ablation:
        settings.append(("line at the interval, no clearance (ablation)", LINE_AT_INTERVAL))
    cells: dict[tuple[str, str, str], dict] = {}
    t0 = time.perf_counter()
    for name, over in settings:
        for scenario in scenarios:
            base = Config(mode="corrected").with_overrides({
                "scenario.kind": scenario, "simulation.n_steps": args.steps, **over})
            for r in rows_of(base, humans, args.seeds, args.workers):
                cells[(name, scenario, r["hv"])] = r
                lo, hi = r["av_first_through_pct_ci"]
                print(f"| {name} | {scenario} | {r['hv']} | {r['both_cleared_pct']:.1f} | "
                      f"{r['deadlocks']} | {r['av_first_through_pct']:.1f} [{lo:.1f}, "
                      f"{hi:.1f}] | {r['collisions_caused_by_av']} | {r['uncertified_steps']} "
                      f"| {r['min_gap_m_min']:.3f} |", flush=True)
    print(f"wall time: {time.perf_counter() - t0:.0f} s")
    ok = []
    for m in margins:
        name = f"clearance {m:g} m"
        bad = []
        for scenario in scenarios:
            for hv in humans:
                r = cells[(name, scenario, hv)]
                if (r["both_cleared_pct"] < BOTH_MIN_PCT or r["deadlocks"]
                        or r["collisions_caused_by_av"] or r["uncertified_steps"]
                        or r["min_gap_m_min"] < m - 1e-6):
                    bad.append(f"{scenario}/{hv}")
            zero = cells.get((f"clearance {margins[0]:g} m", scenario, "lfg"))
            mine = cells.get((name, scenario, "lfg"))
            if zero is not None and mine is not None and margins[0] == 0.0 and \
                    zero["av_first_through_pct"] - mine["av_first_through_pct"] > \
                    PERSUASION_LOSS_MAX_PTS:
                bad.append(f"{scenario}/lfg persuasion "
                           f"{zero['av_first_through_pct'] - mine['av_first_through_pct']:.1f} "
                           "points below no clearance")
        print(f"clearance {m:g} m: " + ("meets the criterion" if not bad
                                        else "fails: " + ", ".join(bad)))
        if not bad:
            ok.append(m)
    print(f"picked: {max(ok):g} m" if ok else "picked: none meets the criterion")


if __name__ == "__main__":
    main()
