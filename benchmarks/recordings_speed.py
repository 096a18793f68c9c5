"""How fast recorded tracks are read and paired (docs/guide/recordings.md).

Writes a synthetic INTERACTION-format folder into a temporary folder: ``--files`` recordings
(default 10) of ``--tracks`` tracks each (default 1000, 10,000 in all, about 100 MB), each a
four-arm intersection of two two-lane roads crossing at right angles. A vehicle arrives on one
of the four approaches (uniformly), 60 m before the junction, every 1.2 s on average
(exponential headways, the same arrival rate on every approach), drives straight through or
(one in five) turns right into the crossing road, at a speed of its own (uniform 7 to 13
m/s), braking to 4 m/s on 20 m before the junction with probability 0.3, and is recorded for
120 m of path; positions carry uniform noise of 5 cm. Then it times
``read_tracks`` + ``smooth_tracks`` + ``find_pairs`` on the folder, the median of
``--repeat`` (default 3) runs in one process (the compiled pair search is compiled and cached
before the first timed run), and prints the figure with the pairs found.

    python benchmarks/recordings_speed.py [--files 10] [--tracks 1000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

#: The four approaches: unit direction of travel; lanes are 3.5 m wide, traffic keeps right.
APPROACHES = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
LANE_M = 3.5
BEFORE_M, PATH_M = 60.0, 140.0


def _path(direction, turn: bool, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre and heading at arc ``s`` from the start, 60 m before the junction's centre."""
    d = np.array(direction)
    right = np.array([d[1], -d[0]])
    start = -BEFORE_M * d + 0.5 * LANE_M * right
    if not turn:
        p = start[None, :] + s[:, None] * d[None, :]
        return p[:, 0], p[:, 1], np.full(s.shape, math.atan2(d[1], d[0]))
    # straight to the arc's start, a quarter circle to the right of radius r, straight on
    r = 6.0
    s0 = BEFORE_M - 0.5 * LANE_M - r
    arc = 0.5 * math.pi * r
    centre = start + s0 * d + r * right
    out = np.empty((s.shape[0], 2))
    heading = np.empty(s.shape[0])
    h0 = math.atan2(d[1], d[0])
    a = s < s0
    out[a] = start + s[a, None] * d
    heading[a] = h0
    b = (s >= s0) & (s < s0 + arc)
    phi = (s[b] - s0) / r
    rel = -r * right  # from the arc's centre to the start of the arc
    rot = np.stack([np.cos(-phi), np.sin(-phi)], axis=1)
    out[b, 0] = centre[0] + rel[0] * rot[:, 0] - rel[1] * rot[:, 1]
    out[b, 1] = centre[1] + rel[0] * rot[:, 1] + rel[1] * rot[:, 0]
    heading[b] = h0 - phi
    c = s >= s0 + arc
    end = centre + r * d
    out[c] = end + (s[c, None] - s0 - arc) * right
    heading[c] = math.atan2(right[1], right[0])
    return out[:, 0], out[:, 1], heading


def write_folder(folder: Path, files: int, tracks: int, seed: int = 0) -> int:
    """Write the synthetic recordings; their total size [bytes]."""
    import pandas as pd

    rng = np.random.default_rng(seed)
    total = 0
    for f in range(files):
        parts = []
        t_arrive = np.cumsum(rng.exponential(1.2, tracks))
        for tid in range(tracks):
            approach = APPROACHES[rng.integers(4)]
            turn = rng.random() < 0.2
            v_free = rng.uniform(7.0, 13.0)
            brake = rng.random() < 0.3
            # speed profile along the path: free, or down to 4 m/s over the 20 m before the
            # junction and back up after it
            t, s, v = [0.0], [0.0], [v_free]
            while s[-1] < PATH_M:
                target = 4.0 if brake and BEFORE_M - 20.0 <= s[-1] < BEFORE_M else v_free
                a = max(-3.0, min(1.5, (target - v[-1]) / 1.0))
                v.append(max(v[-1] + a * 0.1, 0.5))
                s.append(s[-1] + 0.5 * (v[-1] + v[-2]) * 0.1)
                t.append(t[-1] + 0.1)
            s_arr, v_arr = np.array(s), np.array(v)
            x, y, h = _path(approach, turn, s_arr)
            n = s_arr.shape[0]
            frame0 = int(round(t_arrive[tid] * 10))
            parts.append(pd.DataFrame({
                "track_id": tid + 1, "frame_id": np.arange(1, n + 1),
                "timestamp_ms": (frame0 + np.arange(n)) * 100, "agent_type": "car",
                "x": x + rng.uniform(-0.05, 0.05, n), "y": y + rng.uniform(-0.05, 0.05, n),
                "vx": v_arr * np.cos(h), "vy": v_arr * np.sin(h), "psi_rad": h,
                "length": 4.6, "width": 1.9}))
        path = folder / f"vehicle_tracks_{f:03d}.csv"
        pd.concat(parts, ignore_index=True).to_csv(path, index=False, float_format="%.3f")
        total += path.stat().st_size
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", type=int, default=10)
    parser.add_argument("--tracks", type=int, default=1000, help="tracks per file")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.pairs import find_pairs, summary
    from persuasive.recordings.tracks import smooth_tracks

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        size = write_folder(folder, args.files, args.tracks)
        print(f"wrote {args.files} files, {args.files * args.tracks} tracks, "
              f"{size / 1e6:.1f} MB in {time.perf_counter() - t0:.1f} s")
        # compile (and cache) the pair search on the first file, untimed
        find_pairs(smooth_tracks(read_tracks([folder / "vehicle_tracks_000.csv"])))
        times, read_times = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            table = read_tracks([folder])
            t1 = time.perf_counter()
            result = find_pairs(smooth_tracks(table))
            times.append(time.perf_counter() - t0)
            read_times.append(t1 - t0)
        info = summary(result)
    print(f"read + pair: median {statistics.median(times):.2f} s of {args.repeat} "
          f"({', '.join(f'{t:.2f}' for t in times)}); reading alone: median "
          f"{statistics.median(read_times):.2f} s; {os.cpu_count()} cores")
    print(f"{info['vehicle_tracks']} vehicle tracks, {info['candidates']} candidate pairs, "
          f"{info['pairs']} pairs ({info['crossing']} crossing, {info['merge']} merge)")


if __name__ == "__main__":
    main()
