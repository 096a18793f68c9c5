"""How fast ``recordings replay`` runs, and whether another copy of the code replays the same
runs (issue 42 item 2; docs/guide/recordings.md, "Replay").

    python benchmarks/replay_speed.py PAIRS.parquet [--pairs 100] [--pet-max 4] [--workers 1]
                                      [--repeat 3] [--against SRC] [--out DIR]

Takes the pairs of ``PAIRS.parquet`` (``recordings pairs --out``; the site of
``benchmarks/site_recording.py`` is the issue's) whose PET at the conflict area is at
most ``--pet-max`` (``inf``: all; a pair without one is kept, as ``recordings replay`` keeps it),
``--pairs`` of them spread evenly over the file (every k-th), and replays them with the
command's settings (AV persuasive, worst-case shield, both seats, the recorded driver) on
``--workers`` processes. Each timed replay runs in a fresh process, after one untimed pair
there that loads the compiled kernels; the wall time is the replay's alone (reading the file
is not in it). With ``--against SRC`` (the ``src`` folder of another copy of the package, e.g.
``git worktree add /tmp/replay_old HEAD``) every repeat runs that copy right after this one,
on the same pairs, so that the load of a shared machine falls on both alike; it prints both
medians, their ratio and each repeat's, and whether the two replayed the same runs, field for
field (the table ``--out`` of ``recordings replay`` writes). ``--out DIR`` keeps each
replay's table there.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve()
SRC = HERE.parent.parent / "src"


def chosen_pairs(pairs_file: str, n: int, pet_max: float) -> list[int]:
    """``n`` pair IDs spread evenly over the pairs at most ``pet_max`` apart at the conflict
    area (or without a PET)."""
    import pyarrow.parquet as pq

    table = pq.read_table(pairs_file, columns=["pair", "pet_area_s"]).to_pandas()
    pet = table.groupby("pair", sort=True)["pet_area_s"].first()
    keep = pet.index[~(pet > pet_max)]
    step = max(1, len(keep) // max(n, 1))
    return [int(p) for p in keep[::step][:n]]


def child(pairs_file: str, ids_file: str, out: str, workers: int) -> None:
    """One timed replay, in this process (run by :func:`timed` with the copy's PYTHONPATH)."""
    import time

    import persuasive
    from persuasive.recordings.pairs import read_pairs
    from persuasive.recordings.replay import ReplaySettings, replay_pairs

    ids = json.loads(Path(ids_file).read_text())
    frame, _ = read_pairs(pairs_file)
    sub = frame[frame["pair"].isin(ids)]
    sub.attrs = dict(frame.attrs)
    first = frame[frame["pair"] == ids[0]]
    first.attrs = dict(frame.attrs)
    replay_pairs(first, ReplaySettings(seats=(1,)))  # loads (or compiles) the kernels
    t0 = time.perf_counter()
    result = replay_pairs(sub, ReplaySettings(), workers=workers)
    wall = time.perf_counter() - t0
    result.frame().to_parquet(out, index=False)
    print(json.dumps({"wall_s": wall, "runs": len(result.runs),
                      "package": str(Path(persuasive.__file__).parent)}))


def timed(src: Path, pairs_file: str, ids_file: str, out: str, workers: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(src)}
    done = subprocess.run([sys.executable, str(HERE), "--child", pairs_file, ids_file, out,
                           str(workers)], env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"the replay under {src} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def same_runs(a: str, b: str) -> str:
    """"same" when the two tables are equal field for field, else what differs."""
    import pandas as pd

    x, y = pd.read_parquet(a), pd.read_parquet(b)
    try:
        pd.testing.assert_frame_equal(x, y, check_exact=True)
    except AssertionError as exc:
        return f"DIFFERENT: {str(exc).splitlines()[0]}"
    return "same"


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(*sys.argv[2:5], int(sys.argv[5]))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pairs_file")
    ap.add_argument("--pairs", type=int, default=100)
    ap.add_argument("--pet-max", type=float, default=4.0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", default=None, help="another copy's src folder")
    ap.add_argument("--out", default=None, help="keep each replay's table in this folder")
    args = ap.parse_args()
    if args.pairs < 1 or args.repeat < 1 or args.workers < 1 or not args.pet_max > 0:
        ap.error("--pairs, --repeat and --workers are at least 1, --pet-max above 0")
    ids = chosen_pairs(args.pairs_file, args.pairs, args.pet_max)
    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="replay_speed_"))
    work.mkdir(parents=True, exist_ok=True)
    ids_file = work / "pairs.json"
    ids_file.write_text(json.dumps(ids))
    copies = [("this", SRC)] + ([("against", Path(args.against))] if args.against else [])
    pet = "all" if math.isinf(args.pet_max) else f"PET at the area at most {args.pet_max:g} s"
    print(f"{len(ids)} pairs ({pet}) of {args.pairs_file}, {args.workers} worker(s), "
          f"{args.repeat} repeat(s)")
    walls: dict[str, list[float]] = {name: [] for name, _ in copies}
    for r in range(args.repeat):
        tables = {}
        for name, src in copies:
            out = str(work / f"runs-{name}-{r}.parquet")
            got = timed(src, args.pairs_file, str(ids_file), out, args.workers)
            walls[name].append(got["wall_s"])
            tables[name] = out
            print(f"  repeat {r + 1}, {name} ({got['package']}): {got['wall_s']:.2f} s, "
                  f"{got['runs']} runs, {got['wall_s'] / max(got['runs'], 1) * 1e3:.0f} ms "
                  "per run", flush=True)
        if args.against:
            print(f"  repeat {r + 1}: {walls['this'][-1] / walls['against'][-1]:.3f} of the "
                  f"other's time; runs {same_runs(tables['this'], tables['against'])}",
                  flush=True)
    for name, w in walls.items():
        print(f"{name}: median {statistics.median(w):.2f} s of {len(w)} ({min(w):.2f}-"
              f"{max(w):.2f} s)")
    if args.against:
        ratio = statistics.median(walls["this"]) / statistics.median(walls["against"])
        print(f"ratio of the medians (this / against): {ratio:.3f}")


if __name__ == "__main__":
    main()
