"""The yield line's frontier in our simulator: persuasion against standoffs (docs/method.md §12.8).

    python benchmarks/yield_frontier.py [--lines 0,3.75,5] [--margins 0] [--seeds 200]
                                        [--steps 200] [--scenario intersection]
                                        [--hv lfg,idm,...]

For each ``av.yield_line_m`` in ``--lines`` and each clearance ``av.shield_margin_m`` in
``--margins`` runs ``persuasive compare`` (corrected mode, the
worst-case shield, the persuasive planner) against each human of ``--hv`` on seeds 1..N with
``simulation.n_steps = --steps``, and prints one row per (line, human): both vehicles through,
the AV first through the conflict point with both through (with its 95 % interval), standoffs
(neither advanced 0.5 m in 3 s, neither cleared), the longer wait of the two (p95, max), the AV's
time to clear as a restricted mean over all runs, AV-caused collisions, uncertified steps and
the closest the footprints came (runs with a rear-end by the human left out). The
line at 0 is the shield without a line; at the paper's intersection 3.75 m puts it on the 7.5 m
circle around the conflict point. Runs in this process's worker pool (``--workers``).
"""

from __future__ import annotations

import argparse
import tempfile

from persuasive.config import Config
from persuasive.studies.compare import parse_kinds, run_comparison

HUMANS = ("lfg", "noisy", "idm", "stubborn", "aggressive")


def study_args(doc: str, lines: str) -> argparse.ArgumentParser:
    """The options of a study over yield lines and humans (this script's and
    ``oracle_ceiling.py``'s): ``--lines`` (default ``lines``), ``--seeds``, ``--steps``,
    ``--scenario``, ``--hv``, ``--workers``."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--lines", default=lines)
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--scenario", default="intersection")
    parser.add_argument("--hv", default=",".join(HUMANS))
    parser.add_argument("--workers", type=int, default=None)
    return parser


def humans_and_lines(args) -> tuple[list[str], list[float]]:
    """The humans of ``--hv`` (checked) and the lines of ``--lines``."""
    humans = parse_kinds(args.hv, HUMANS + ("adversary", "deceptive", "random"), "--hv", HUMANS)
    return humans, [float(x) for x in args.lines.split(",")]


def main() -> None:
    parser = study_args(__doc__, "0,3.75,5")
    parser.add_argument("--margins", default="0")
    args = parser.parse_args()
    humans, lines = humans_and_lines(args)
    print(f"{args.scenario}, corrected mode, worst-case shield, persuasive AV, seeds "
          f"1..{args.seeds}, {args.steps} steps")
    margins = [float(x) for x in args.margins.split(",")]
    print("| yield line m | margin m | human | both through % | AV first through % [95 % CI] | "
          "standoffs | wait p95 / max s | AV clear s (restricted mean) | AV-caused | "
          "uncertified | min gap m |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for line, margin in ((x, m) for x in lines for m in margins):
        base = Config(mode="corrected").with_overrides({
            "scenario.kind": args.scenario, "simulation.n_steps": args.steps,
            "av.yield_line_m": line, "av.shield_margin_m": margin})
        with tempfile.TemporaryDirectory() as tmp:
            summary = run_comparison(base, ("persuasive",), humans, args.seeds,
                                     out=f"{tmp}/compare", workers=args.workers,
                                     timing_seeds=1).summary
        for r in summary["rows"]:
            lo, hi = r["av_first_through_pct_ci"]
            print(f"| {line:g} | {margin:g} | {r['hv']} | {r['both_cleared_pct']:.1f} | "
                  f"{r['av_first_through_pct']:.1f} [{lo:.1f}, {hi:.1f}] | {r['deadlocks']} | "
                  f"{r['wait_s_p95']:.1f} / {r['wait_s_max']:.1f} | "
                  f"{r['av_clear_s_rmean']:.2f} | {r['collisions_caused_by_av']} | "
                  f"{r['uncertified_steps']} | {r['min_gap_m_min']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
