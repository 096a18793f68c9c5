"""Where the junction's AV persuades, conflict by conflict (docs/results.md §16.6).

    python benchmarks/junction_persuasion.py [--vehicles 2,3,4,6,8,10] [--seeds 500]
                                             [--av persuasive,passive] [--workers 2]
                                             [--set KEY=VALUE ...] [--json FILE]

Runs the junction (corrected mode, 60-s runs, its defaults otherwise; ``--set`` for any
configuration key, e.g. ``junction.av_line=stop``) for each AV kind of ``--av``, number of
vehicles and seed, and reads every crossing and merge of the AV that both vehicles passed
(``persuasive.many.measures.passings``). Each is put in a class by what the AV met there:

- **right of way**: the AV's, the human's, or neither (the conflict table's row);
- **the human's place**: first in its lane at the start, or behind another vehicle there;
- **the AV had stood**: below ``persuasive.tables.STAND_V_MPS`` (0.1 m/s) at some step before
  the first of the two passed the conflict point.

It prints, per AV kind and N, the share of the conflicts the AV passed first overall and in
each class (how many in parentheses), and how the conflicts fall into the classes. The
classes are the frontier of persuasion against a crowd: against one human the AV meets it
first, moving; with more humans more of its conflicts are with a human queued behind
another or met after the AV has stood, where passing first means going before a human that
is already moving into a gap the AV has not taken.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from persuasive._files import atomic_write
from persuasive.config import Config, ConfigError
from persuasive.many.measures import passings
from persuasive.many.world import JunctionWorld
from persuasive.sweep.runner import run_all
from persuasive.tables import STAND_V_MPS

ROW = ("AV's", "human's", "neither")


def conflicts_of(config: Config, seed: int) -> list[dict]:
    """The AV's crossings and merges both passed in run ``seed`` (module docstring)."""
    world = JunctionWorld.of(config, seed).run()
    arr, dt = world.arrivals, world.dt
    ahead = [sum(1 for k in range(arr.n) if k != j and arr.routes[k].inbound ==
                 arr.routes[j].inbound and arr.s0_m[k] > arr.s0_m[j]) for j in range(arr.n)]
    prio = {(r.i, r.j): r.priority for r in world.table.rows}
    v_av = world.V[: world.k + 1, 0]
    out = []
    for i, j, ti, tj in passings(world):
        if i != 0:
            continue
        first = int(np.floor(min(ti, tj) / dt))
        before = v_av[: first + 1]
        out.append({"seed": seed, "human": j, "av_first": bool(ti < tj),
                    "right_of_way": ROW[{1: 0, -1: 1, 0: 2}[prio[(i, j)]]],
                    "queued": ahead[j] > 0,
                    "av_stood": bool(np.any(before[np.isfinite(before)] < STAND_V_MPS))})
    return out


def _task(task: tuple) -> list[dict]:
    overrides, seeds = task
    config = Config(mode="corrected").with_overrides(overrides)
    return [c for s in seeds for c in conflicts_of(config, s)]


def _share(rows: list[dict]) -> str:
    if not rows:
        return "-"
    first = sum(r["av_first"] for r in rows)
    return f"{100.0 * first / len(rows):.1f} % ({len(rows)})"


def table(results: dict) -> str:
    """The markdown table of ``results`` ``{(kind, n): conflicts}``."""
    lines = ["| AV | vehicles | AV first: all | AV's right of way | human's right of way | "
             "human first in lane | human queued | AV moving until then | AV had stood | "
             "queued or stood [% of conflicts] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (kind, n), rows in results.items():
        def of(pred):
            return [r for r in rows if pred(r)]
        late = len(of(lambda r: r["queued"] or r["av_stood"]))
        lines.append(
            f"| {kind} | {n} | {_share(rows)} | "
            f"{_share(of(lambda r: r['right_of_way'] == ROW[0]))} | "
            f"{_share(of(lambda r: r['right_of_way'] == ROW[1]))} | "
            f"{_share(of(lambda r: not r['queued']))} | {_share(of(lambda r: r['queued']))} | "
            f"{_share(of(lambda r: not r['av_stood']))} | "
            f"{_share(of(lambda r: r['av_stood']))} | "
            f"{(100.0 * late / len(rows)) if rows else 0.0:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", default="2,3,4,6,8,10")
    parser.add_argument("--seeds", type=int, default=500)
    parser.add_argument("--av", default="persuasive,passive")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--json", default=None, metavar="FILE")
    args = parser.parse_args(argv)
    try:
        vehicles = [int(x) for x in args.vehicles.split(",") if x.strip()]
        if args.seeds < 1:
            raise ConfigError(f"--seeds = {args.seeds} is out of range; allowed: >= 1")
        extra = {}
        for item in args.set:
            key, sep, value = item.partition("=")
            if not sep:
                raise ConfigError(f"--set {item!r} is not KEY=VALUE")
            extra[key] = value
        kinds = [k for k in args.av.split(",") if k]
        cells, tasks = [], []
        for kind in kinds:
            for n in vehicles:
                overrides = {"scenario.kind": "junction", "junction.duration_s": 60.0,
                             "junction.n_vehicles": n, "av.kind": kind, **extra}
                Config(mode="corrected").with_overrides(overrides).junction_spec  # checked
                chunks = np.array_split(np.arange(1, args.seeds + 1), max(1, args.seeds // 25))
                for c in chunks:
                    cells.append((kind, n))
                    tasks.append((overrides, [int(s) for s in c]))
    except (ConfigError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()

    def progress(done: int, total: int) -> None:
        print(f"\r{done}/{total} tasks", end="", file=sys.stderr, flush=True)

    parts = run_all(_task, tasks, args.workers, progress)
    print(file=sys.stderr)
    results: dict = {}
    for cell, part in zip(cells, parts):
        results.setdefault(cell, []).extend(part)
    print(f"seeds 1..{args.seeds}; {', '.join(args.set) or 'defaults'}")
    print(table(results))
    print(f"wall time {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if args.json:
        atomic_write(Path(args.json), lambda tmp: tmp.write_text(json.dumps(
            {f"{k}/{n}": rows for (k, n), rows in results.items()})))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
