"""``recordings pairs`` at a site's size, two source trees in one run (docs/guide/recordings.md,
"A site-size recording, made here").

    python benchmarks/site_recording.py site
    python benchmarks/pairs_speed.py OLD_SRC NEW_SRC site [--rounds 2] [--workers 2]

Each round runs ``persuasive recordings pairs site --map site/site.osm --workers W`` once
with each tree (``PYTHONPATH=SRC``; OLD_SRC e.g. a ``git worktree`` of an earlier commit's
``src``), alternately, writing to a temporary folder; prints each run's wall time and the
peak resident memory summed over its process tree (sampled every 50 ms with psutil), and
whether the two trees' pairs files are the same bytes. Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil


def timed(src: str, site: Path, out: Path, workers: int) -> tuple[float, float]:
    """Wall time [s] and peak summed resident memory [GB] of one run."""
    env = {**os.environ, "PYTHONPATH": src}
    cmd = [sys.executable, "-m", "persuasive", "recordings", "pairs", str(site), "--map",
           str(site / "site.osm"), "--out", str(out), "--workers", str(workers), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL)
    root = psutil.Process(proc.pid)
    peak = 0
    while proc.poll() is None:
        total = 0
        try:
            for p in [root, *root.children(recursive=True)]:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    pass
        except psutil.Error:
            pass
        peak = max(peak, total)
        time.sleep(0.05)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{src}: exit {proc.returncode}")
    return wall, peak / 1e9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old_src")
    parser.add_argument("new_src")
    parser.add_argument("site", type=Path)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    walls = {"old": [], "new": []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            outs = {}
            for name, src in (("old", args.old_src), ("new", args.new_src)):
                outs[name] = Path(tmp) / f"{name}.parquet"
                wall, gb = timed(src, args.site, outs[name], args.workers)
                walls[name].append(wall)
                print(f"round {r + 1} {name}: {wall:.2f} s wall, {gb:.2f} GB peak (tree)")
            same = filecmp.cmp(outs["old"], outs["new"], shallow=False)
            print(f"round {r + 1}: the pairs files are {'the same' if same else 'NOT the same'} "
                  "bytes")
    old, new = statistics.median(walls["old"]), statistics.median(walls["new"])
    print(f"median wall: old {old:.2f} s, new {new:.2f} s, new/old {new / old:.3f}")


if __name__ == "__main__":
    main()
