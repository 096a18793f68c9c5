"""The recordings' round trip, replicated: does ``p_a`` survive export, reading, pairing and
fitting? (docs/guide/recordings.md, "The round trip, replicated").

    python benchmarks/recordings_roundtrip.py [--fixtures 50] [--runs 20] [--p-a 0.3,0.7]
                                              [--roles leader,follower] [--noise-m 0.05]
                                              [--noise-mps 0.1] [--speed-from file]
                                              [--no-measurement-model] [--workers 2]
                                              [--out FILE.jsonl]

A *fixture* is ``--runs`` simulated runs of an ``lfg`` human with a known ``roles.p_a`` and
initial role, the design of the parameter-recovery benchmark (``benchmarks/fit_recovery.py``,
docs/method.md §13.7): corrected mode, the 90-degree ``crossing`` (the scenario the pairs are
projected onto), ``simulation.n_steps = 120``, run ``j`` against the persuasive AV when ``j``
is even and the passive AV when odd, both with ``p_a_hat = 1`` and unshielded; fixture ``d``
uses seeds ``1 + runs d + j`` and the ``d``-th setting of the (``p_a``, role) grid, in turn.
Each fixture then goes the whole way a recording goes:

1. ``recordings export``: every run as an INTERACTION file (one recording per run), uniform
   noise ``U(-noise_m, noise_m)`` on ``x`` and ``y`` and ``U(-noise_mps, noise_mps)`` on the
   speed (seed ``d``);
2. read, smoothed (Savitzky-Golay, ``--window`` samples, the pipeline's 7 by default; speed
   and acceleration from the files' speeds, or ``--speed-from positions``), paired
   (``persuasive.recordings.pairs``, default parameters);
3. the logs (``persuasive.recordings.logs.view_log``, the tracks' filter in their metadata):
   vehicle 2 of each pair, the simulated human, as the human (vehicle 1 is the AV, whose view
   is no human's);
4. ``persuasive.fitting.fit_models`` with all four models (``lfg``, ``stubborn``, ``noisy``,
   ``idm``), the ``lfg``'s 95 % profile interval for ``p_a``; the models' accelerations pass
   through the tracks' filter first (the fit's measurement model: the ``lfg`` and ``stubborn``
   over the role paths of each window, ``persuasive.fitting.models.path_loglik``; ``noisy``
   with each candidate held over the window, ``persuasive.fitting.evidence.observe_through``),
   unless ``--no-measurement-model``.

Per fixture: whether the interval covers the true ``p_a``, whether the smallest BIC selects
``lfg`` (the generating kind), the estimate, and the pairs found (a run whose two vehicles
make no pair drops out). The summary: coverage and selection shares over the fixtures
(targets: coverage 90-99 %, selection at least 90 %, over at least 50 fixtures) with 95 %
Wilson intervals, and the mean absolute error. ``--out`` appends one JSON line per fixture.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np


def configs(p_a: float, role: str):
    from persuasive import Config

    base = {"scenario.kind": "crossing", "simulation.n_steps": 120, "hv.kind": "lfg",
            "roles.p_a": p_a, "hv.role": role, "mpc.p_a_hat": 1.0, "av.shield": "off"}
    return [Config(mode="corrected").with_overrides({**base, "av.kind": av})
            for av in ("persuasive", "passive")]


def fixture(d: int, runs: int, p_a: float, role: str, noise_m: float, window: int = 7,
            measurement: bool = True, noise_mps: float = 0.0, speed_from: str = "file") -> dict:
    """One fixture's round trip (module docstring)."""
    from persuasive import Config, simulate
    from persuasive.fitting import evidence_of, fit_models
    from persuasive.fitting.evidence import RunLog
    from persuasive.recordings.export import export_runs
    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.logs import view_log
    from persuasive.recordings.pairs import find_pairs, pairs_frame
    from persuasive.recordings.tracks import SmoothingParams, smooth_tracks

    t0 = time.perf_counter()
    cs = configs(p_a, role)
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for j in range(runs):
            path = Path(tmp) / f"run{j:03d}.parquet"
            simulate(cs[j % 2], 1 + runs * d + j).save(path)
            paths.append(str(path))
        tracks = Path(tmp) / "tracks"
        tracks.mkdir()
        export_runs(paths, tracks, noise_m, d, noise_mps)
        smoothing = SmoothingParams(window=window, speed=speed_from)
        result = find_pairs(smooth_tracks(read_tracks([str(tracks)]), smoothing))
    frame = pairs_frame(result.pairs)
    base = Config(mode="corrected")
    logs = []
    kept = asdict(smoothing) if measurement else None
    for pair_id, rows in frame.groupby("pair", sort=True):
        config, log, meta = view_log(rows.sort_values("step"), 2, base, smoothing=kept)
        states = log[["av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m",
                      "hv_meas_v_mps"]].to_numpy(float)
        logs.append(RunLog(f"pair {int(pair_id)}", config, int(pair_id), None, states,
                           log["hv_accel_mps2"].to_numpy(float), meta))
    ev = evidence_of(logs)
    report = fit_models(ev, intervals=["lfg"])
    e = report.fits["lfg"].params["p_a"]
    return {"fixture": d, "p_a": p_a, "role": role, "noise_m": noise_m,
            "noise_mps": noise_mps, "window": window, "speed_from": speed_from,
            "measurement_model": measurement,
            "runs": runs,
            "pairs": len(result.pairs), "p_hat": e.value, "low": e.low, "high": e.high,
            "covered": bool(e.low - 1e-9 <= p_a <= e.high + 1e-9),
            "selected": report.selected, "sigma_hat": report.fits["lfg"].theta["sigma"],
            "seconds": round(time.perf_counter() - t0, 2)}


def wilson(k: int, n: int, z: float = 1.96) -> str:
    """The 95 % Wilson score interval of ``k`` of ``n``, in per cent."""
    if n == 0:
        return "[nan, nan]"
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return f"[{100 * (centre - half):.0f}, {100 * (centre + half):.0f}] %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fixtures", type=int, default=50)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--p-a", default="0.3,0.7")
    ap.add_argument("--roles", default="leader,follower")
    ap.add_argument("--noise-m", type=float, default=0.05)
    ap.add_argument("--window", type=int, default=7,
                    help="the Savitzky-Golay window [samples] (the pipeline's default: 7)")
    ap.add_argument("--noise-mps", type=float, default=0.1,
                    help="half-width of the uniform noise on the exported speeds [m/s]")
    ap.add_argument("--speed-from", default="file", choices=("file", "positions"),
                    help="the tracks' speed and acceleration: the files' or the positions'")
    ap.add_argument("--no-measurement-model", action="store_true",
                    help="fit the models' accelerations as they are, not as the filter "
                         "records them")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None, help="append one JSON line per fixture")
    args = ap.parse_args()
    grid = [(float(p), r) for p in args.p_a.split(",") for r in args.roles.split(",")]
    measurement = not args.no_measurement_model
    tasks = [(d, args.runs, *grid[d % len(grid)], args.noise_m, args.window, measurement,
              args.noise_mps, args.speed_from) for d in range(args.fixtures)]
    print(f"{args.fixtures} fixtures of {args.runs} runs, noise U(-{args.noise_m:g}, "
          f"{args.noise_m:g}) m and U(-{args.noise_mps:g}, {args.noise_mps:g}) m/s, smoothing "
          f"window {args.window}, speed from the {args.speed_from}, measurement model "
          f"{'on' if measurement else 'off'}, settings (p_a, role) {grid}, {args.workers} "
          "workers", flush=True)
    t0 = time.perf_counter()
    rows = []
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # one thread per worker
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool:
        for row in pool.map(fixture, *zip(*tasks)):
            rows.append(row)
            print(f"  fixture {row['fixture']}: p_a {row['p_a']:g} ({row['role']}), "
                  f"{row['pairs']} pairs, p_hat {row['p_hat']:.3f} [{row['low']:.3f}, "
                  f"{row['high']:.3f}] {'covers' if row['covered'] else 'misses'}, BIC "
                  f"selects {row['selected']}, sigma {row['sigma_hat']:.3f}, "
                  f"{row['seconds']:.1f} s", flush=True)
            if args.out:
                with open(args.out, "a") as fh:
                    fh.write(json.dumps(row) + "\n")
    n = len(rows)
    cover = np.mean([r["covered"] for r in rows])
    select = np.mean([r["selected"] == "lfg" for r in rows])
    mae = np.mean([abs(r["p_hat"] - r["p_a"]) for r in rows])
    width = np.mean([r["high"] - r["low"] for r in rows])
    n_cover = sum(r["covered"] for r in rows)
    n_select = sum(r["selected"] == "lfg" for r in rows)
    print(f"{n} fixtures in {time.perf_counter() - t0:.0f} s: coverage of the 95 % interval "
          f"{100 * cover:.0f} % ({n_cover} of {n}, 95 % CI {wilson(n_cover, n)}; target "
          f"90-99 %), BIC selects lfg in {100 * select:.0f} % ({n_select} of {n}, 95 % CI "
          f"{wilson(n_select, n)}; target >= 90 %); MAE {mae:.3f}, mean interval width "
          f"{width:.3f}")
    picked = {m: sum(r["selected"] == m for r in rows) for m in
              sorted({r["selected"] for r in rows})}
    print("  BIC selects: " + ", ".join(f"{m} {k}" for m, k in picked.items()))
    for (p, role) in grid:
        rs = [r for r in rows if r["p_a"] == p and r["role"] == role]
        if rs:
            print(f"  p_a {p:g}, {role}: {len(rs)} fixtures, coverage "
                  f"{100 * np.mean([r['covered'] for r in rs]):.0f} %, selection "
                  f"{100 * np.mean([r['selected'] == 'lfg' for r in rs]):.0f} %, mean "
                  f"estimate {np.mean([r['p_hat'] for r in rs]):.3f}")


if __name__ == "__main__":
    main()
