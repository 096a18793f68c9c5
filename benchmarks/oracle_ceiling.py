"""How much persuasion a shielded planner could keep with perfect foresight of the human
(issue 25 item 4, the ceiling; docs/method.md §12.12, results §15.15).

    python benchmarks/oracle_ceiling.py [--lines 0,3.75,4.5,6] [--seeds 200] [--steps 200]
                                        [--scenario intersection] [--hv lfg,idm,...]
                                        [--workers N]

The *foresight oracle* is the persuasive planner behind the worst-case shield that, before the
run starts, knows the human's policy exactly, its random stream included, and picks for the run
the yield line ``av.yield_line_m`` from ``--lines`` that ends best: it simulates the whole run
with each line (the simulator is deterministic in the configuration and the seed, so each
simulation *is* the run it would drive) and keeps, in this order of preference
(``persuasive.safety.foresight.score``),

1. a run with both vehicles through and no standoff (``both_cleared`` and not ``deadlock``),
2. the AV first through the conflict point (``av_first_through``),
3. the AV's shorter time to clear (the run's length where it never cleared),

ties to the earlier line of ``--lines``. Every run it picks is a run of the shielded planner, so
it keeps every guarantee of the shield; what it adds is only the choice. The rows it prints,
one per human, beside one row per fixed line: both vehicles through, AV first through (with its
95 % bootstrap interval over seeds), standoffs, AV-caused collisions, uncertified steps, the
AV's time to clear (restricted mean over all runs), and for the oracle how often it picked
each line. This is a ceiling for *choosing the line*: a planner that predicts the human as
well as the oracle does can choose as well; it is not a ceiling over every trajectory.
"""

from __future__ import annotations

import tempfile

import numpy as np
import pandas as pd
from yield_frontier import humans_and_lines, study_args  # this folder's (same options)

from persuasive.config import Config
from persuasive.studies.compare import run_comparison


def line_runs(base: Config, lines: list[float], humans, seeds: int, workers) -> pd.DataFrame:
    """Every (line, human, seed) run, one row each, with the line in column ``line``."""
    frames = []
    for line in lines:
        config = base.with_overrides({"av.yield_line_m": line})
        with tempfile.TemporaryDirectory() as tmp:
            runs = run_comparison(config, ("persuasive",), humans, seeds, out=f"{tmp}/compare",
                                  workers=workers, timing_seeds=1).runs
        frames.append(runs.assign(line=line))
    return pd.concat(frames, ignore_index=True)


def choose(runs: pd.DataFrame, lines: list[float], run_s: float) -> pd.DataFrame:
    """The oracle's pick per (human, seed): the run of the best
    ``persuasive.safety.foresight.score`` (foresight's own order of preference), ties to the
    earlier line."""
    from persuasive.safety.foresight import score

    order = {line: i for i, line in enumerate(lines)}
    keys = [(*score(r, run_s), -order[r["line"]]) for r in runs.to_dict("records")]
    ranked = runs.assign(_key=keys).sort_values(["hv.kind", "seed", "_key"],
                                                ascending=[True, True, False])
    return ranked.groupby(["hv.kind", "seed"], sort=False).head(1)


def row(label: str, human: str, runs: pd.DataFrame, run_s: float, picks: str = "") -> str:
    """One markdown row of the table."""
    rng = np.random.default_rng(0)
    first = runs["av_first_through"].to_numpy(dtype=float)
    boot = [first[rng.integers(0, first.size, first.size)].mean() for _ in range(2000)]
    lo, hi = 100 * np.percentile(boot, [2.5, 97.5])
    clear = runs["av_time_to_clear_s"].fillna(run_s).clip(upper=run_s).mean()
    return (f"| {label} | {human} | {100 * runs['both_cleared'].mean():.1f} | "
            f"{100 * first.mean():.1f} [{lo:.1f}, {hi:.1f}] | {int(runs['deadlock'].sum())} | "
            f"{int(runs['collision_caused_by_av'].sum())} | {int(runs['uncertified_steps'].sum())} "
            f"| {clear:.2f} | {picks} |")


def main() -> None:
    args = study_args(__doc__, "0,3.75,4.5,6").parse_args()
    humans, lines = humans_and_lines(args)
    base = Config(mode="corrected").with_overrides({
        "scenario.kind": args.scenario, "simulation.n_steps": args.steps})
    run_s = args.steps * base.simulation.dt_s
    runs = line_runs(base, lines, humans, args.seeds, args.workers)
    picked = choose(runs, lines, run_s)
    print(f"{args.scenario}, corrected mode, worst-case shield, persuasive AV, seeds "
          f"1..{args.seeds}, {args.steps} steps; the oracle picks among lines "
          f"{', '.join(f'{x:g}' for x in lines)} m")
    print("| yield line m | human | both through % | AV first through % [95 % CI] | standoffs "
          "| AV-caused | uncertified | AV clear s (restricted mean) | oracle's lines |")
    print("|---|---|---|---|---|---|---|---|---|")
    for human in humans:
        for line in lines:
            sel = runs[(runs["hv.kind"] == human) & (runs["line"] == line)]
            print(row(f"{line:g}", human, sel, run_s))
        sel = picked[picked["hv.kind"] == human]
        counts = sel["line"].value_counts()
        picks = ", ".join(f"{x:g}: {int(counts.get(x, 0))}" for x in lines)
        print(row("oracle", human, sel, run_s, picks), flush=True)


if __name__ == "__main__":
    main()
