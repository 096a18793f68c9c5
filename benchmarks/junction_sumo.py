"""SUMO's own driver against our planner at the four-way junction, paired by seed
(issue 41 item 3; persuasive.many.sumo, docs/guide/junction.md "Against SUMO's own driver").

    python benchmarks/junction_sumo.py [--vehicles 2,3,4,6,8,10] [--seeds 100] [--seed 1]
        [--workers K] [--av persuasive[,passive,...]] [--shield worst-case]
        [--variant major] [--lanes 1] [--av-start stoppable|drawn] [--out DIR]

For every number of vehicles N (the AV included) and every seed, builds our junction
(``JunctionSpec.of(variant, n_vehicles=N, lanes=..., av_start=...)``) in SUMO with the seed's arrivals and
runs it three ways among the same SUMO-driven humans: without the AV (the reference of the
time the others lose), with the AV driven by SUMO's own driver, and with the AV driven by each
planner of ``--av`` behind ``--shield``. Prints one row per N and planner:

- AV through: the AV's rear out of the box within 60 s of its depart, in % of the seeds, for
  SUMO's driver and ours; the paired difference (ours - SUMO's, in points) with the normal
  95 % interval of the mean paired difference over seeds (mean +- 1.96 s / sqrt(n));
- the AV's time to clear (restricted mean: a seed not through counts 60 s);
- the delay caused to the others: their tripinfo timeLoss summed, less the run without the AV,
  per human, mean over seeds; and its paired difference with the same interval;
- collisions SUMO reports: AV-caused (every one with the AV but a rear-end into it) and
  between two humans; the lowest PET SUMO's SSM device saw on the AV; the shield's overrides
  and uncertified steps.

The numbers depend on the seeds only, not on ``--workers`` (each seed runs in one worker
process); the wall time is printed apart. ``--out DIR`` writes ``study.json`` (the table and
every episode) and ``table.md``, each atomically (a temporary file, then a rename).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from persuasive._files import atomic_write
from persuasive.config import ConfigError
from persuasive.many.sumo import run_study

HEADER = ("| N | AV | seeds | through 60 s % SUMO | through 60 s % ours | difference points "
          "[95 % CI] | time to clear s SUMO / ours | delay caused s per human SUMO / ours | "
          "difference s [95 % CI] | AV-caused collisions SUMO / ours | human collisions SUMO / "
          "ours | min PET s SUMO / ours | overrides % | uncertified |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def _num(x, fmt: str = ".2f") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    text = format(x, fmt)
    return format(0.0, fmt) if float(text) == 0.0 else text  # no "-0.00"


def _ci(lo, hi, fmt: str) -> str:
    return f"[{_num(lo, fmt)}, {_num(hi, fmt)}]"


def row_md(r: dict) -> str:
    """One table row of :meth:`persuasive.many.sumo.Study.table`'s entry ``r``."""
    av = r["driver"].split("/")[0]
    return (f"| {r['n_vehicles']} | {av} | {r['seeds']} | {r['through_pct_sumo']:.1f} | "
            f"{r['through_pct_ours']:.1f} | {_num(r['through_diff_points'], '+.1f')} "
            f"{_ci(*r['through_diff_ci'], '+.1f')} | {_num(r['clear_s_sumo'])} / "
            f"{_num(r['clear_s_ours'])} | {_num(r['caused_delay_s_sumo'])} / "
            f"{_num(r['caused_delay_s_ours'])} | {_num(r['delay_diff_s'], '+.2f')} "
            f"{_ci(*r['delay_diff_ci'], '+.2f')} | {r['av_caused_collisions_sumo']} / "
            f"{r['av_caused_collisions_ours']} | {r['human_collisions_sumo']} / "
            f"{r['human_collisions_ours']} | {_num(r['min_pet_s_sumo'])} / "
            f"{_num(r['min_pet_s_ours'])} | {r['override_pct']:.1f} | {r['uncertified']} |")


def _ints(text: str, name: str) -> list[int]:
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ConfigError(f"{name} = {text!r} is not a comma-separated list of integers") \
            from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", default="2,3,4,6,8,10")
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--av", default="persuasive")
    parser.add_argument("--shield", default="worst-case")
    parser.add_argument("--variant", default="major")
    parser.add_argument("--lanes", type=int, default=1)
    parser.add_argument("--av-start", default="stoppable", choices=["stoppable", "drawn"],
                        help="junction.av_start: the AV's initial speed capped so that it can "
                             "stop before its first line (default), or as drawn")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    try:
        vehicles = _ints(args.vehicles, "--vehicles")
        avs = [a for a in args.av.split(",") if a]
        out = Path(args.out) if args.out else None
        if out is not None and out.exists() and not out.is_dir():
            raise ConfigError(f"--out = {args.out!r} is a file; allowed: a folder")
        t0 = time.perf_counter()

        def progress(done: int, total: int) -> None:
            print(f"\r{done}/{total} seeds", end="", file=sys.stderr, flush=True)

        study = run_study(vehicles, args.seeds, args.seed, avs, args.shield, args.workers,
                          args.variant, args.lanes, progress=progress,
                          av_start=args.av_start)
        print(file=sys.stderr)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    table = "\n".join([HEADER] + [row_md(r) for r in study.table()])
    print(f"variant {args.variant}, {args.lanes} lane(s); seeds {args.seed}.."
          f"{args.seed + args.seeds - 1}; shield {args.shield}; SUMO: its own driver as the AV")
    print(table)
    print(f"wall time {time.perf_counter() - t0:.0f} s on {study.workers} worker(s)",
          file=sys.stderr)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / "study.json", lambda tmp: tmp.write_text(
            json.dumps(study.to_dict(), indent=1, allow_nan=False) + "\n",
            encoding="utf-8"))
        atomic_write(out / "table.md", lambda tmp: tmp.write_text(table + "\n",
                                                                   encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
