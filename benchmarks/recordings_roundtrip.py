"""The recordings' round trip, replicated: does ``p_a`` survive export, reading, pairing and
fitting? (docs/guide/recordings.md, "The round trip, replicated").

    python benchmarks/recordings_roundtrip.py [--fixtures 50] [--runs 20] [--p-a 0.3,0.7]
                                              [--roles leader,follower] [--noise-m 0.05]
                                              [--workers 2] [--out FILE.jsonl]

A *fixture* is ``--runs`` simulated runs of an ``lfg`` human with a known ``roles.p_a`` and
initial role, the design of the parameter-recovery benchmark (``benchmarks/fit_recovery.py``,
docs/method.md §13.7): corrected mode, the 90-degree ``crossing`` (the scenario the pairs are
projected onto), ``simulation.n_steps = 120``, run ``j`` against the persuasive AV when ``j``
is even and the passive AV when odd, both with ``p_a_hat = 1`` and unshielded; fixture ``d``
uses seeds ``1 + runs d + j`` and the ``d``-th setting of the (``p_a``, role) grid, in turn.
Each fixture then goes the whole way a recording goes:

1. ``recordings export``: every run as an INTERACTION file (one recording per run), uniform
   noise ``U(-noise, noise)`` on ``x`` and ``y`` (seed ``d``);
2. read, smoothed (Savitzky-Golay, ``--window`` samples, the pipeline's 11 by default),
   paired (``persuasive.recordings.pairs``, default parameters);
3. the logs (``persuasive.recordings.logs.view_log``): vehicle 2 of each pair, the simulated
   human, as the human (vehicle 1 is the AV, whose view is no human's);
4. ``persuasive.fitting.fit_models`` with all four models (``lfg``, ``stubborn``, ``noisy``,
   ``idm``), the ``lfg``'s 95 % profile interval for ``p_a``.

``--model-smoothing``: before the fit, the models' accelerations (each role's, and each
candidate trajectory's first one) pass through the pipeline's own smoothing as the recorded
ones did: the centred Savitzky-Golay position filter, then its second derivative, as one
kernel over the steps around each (its impulse response; the role and the candidate held over
the window, the view's ends repeated). A test of whether smoothing explains the fitted noise,
not part of ``persuasive fit``.

Per fixture: whether the interval covers the true ``p_a``, whether the smallest BIC selects
``lfg`` (the generating kind), the estimate, and the pairs found (a run whose two vehicles
make no pair drops out). The summary: coverage and selection shares over the fixtures
(targets: coverage 90-99 %, selection at least 90 %, over at least 50 fixtures) and the mean
absolute error. ``--out`` appends one JSON line per fixture.
"""

from __future__ import annotations

import argparse
import json
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


def smoothing_kernel(window: int) -> dict[int, float]:
    """``{d: w_d}``: the smoothed acceleration at step ``k`` is ``sum_d w_d a_{k+d}`` for the
    true accelerations ``a`` (exact kinematics, 0.1 s steps), away from a track's ends: the
    pipeline's centred Savitzky-Golay filter of the positions, then its second derivative
    (``persuasive.recordings.tracks``), applied to a unit impulse."""
    from persuasive.recordings.tracks import STEP_S, SmoothingParams, savgol

    order = SmoothingParams(window=window).order
    h = window // 2
    n, j0, dt = 8 * window + 1, 4 * window, STEP_S

    def observed(a):
        v = 10.0 + np.concatenate([[0.0], np.cumsum(a[:-1]) * dt])
        s = np.concatenate([[0.0], np.cumsum(v[:-1] * dt + 0.5 * a[:-1] * dt * dt)])
        starts = np.array([0, n], np.int64)
        return savgol(savgol(s, starts, window, order), starts, window, order, 2)

    impulse = np.zeros(n)
    impulse[j0] = 1.0
    r = observed(impulse) - observed(np.zeros(n))
    return {j0 - k: float(r[k]) for k in range(j0 - 2 * h, j0 + 2 * h + 1)}


def smooth_models(ev, kernel: dict[int, float]) -> None:
    """The evidence's model accelerations ``a_role`` and ``a_first`` through ``kernel``, run by
    run, in place (the view's first and last steps repeated beyond its ends)."""
    for i in range(ev.n_runs):
        a, b = ev.starts[i], ev.starts[i + 1]
        idx = np.arange(b - a)
        for arr in (ev.a_role, ev.a_first):
            seg = arr[a:b].copy()
            out = np.zeros_like(seg)
            for d, w in kernel.items():
                out += w * seg[np.clip(idx + d, 0, b - a - 1)]
            arr[a:b] = out


def fixture(d: int, runs: int, p_a: float, role: str, noise_m: float, window: int = 11,
            model_smoothing: bool = False) -> dict:
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
        export_runs(paths, tracks, noise_m, d)
        result = find_pairs(smooth_tracks(read_tracks([str(tracks)]),
                                          SmoothingParams(window=window)))
    frame = pairs_frame(result.pairs)
    base = Config(mode="corrected")
    logs = []
    for pair_id, rows in frame.groupby("pair", sort=True):
        config, log, meta = view_log(rows.sort_values("step"), 2, base)
        states = log[["av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m",
                      "hv_meas_v_mps"]].to_numpy(float)
        logs.append(RunLog(f"pair {int(pair_id)}", config, int(pair_id), None, states,
                           log["hv_accel_mps2"].to_numpy(float), meta))
    ev = evidence_of(logs)
    if model_smoothing:
        smooth_models(ev, smoothing_kernel(window))
    report = fit_models(ev, intervals=["lfg"])
    e = report.fits["lfg"].params["p_a"]
    return {"fixture": d, "p_a": p_a, "role": role, "noise_m": noise_m, "window": window,
            "model_smoothing": model_smoothing,
            "runs": runs,
            "pairs": len(result.pairs), "p_hat": e.value, "low": e.low, "high": e.high,
            "covered": bool(e.low - 1e-9 <= p_a <= e.high + 1e-9),
            "selected": report.selected, "sigma_hat": report.fits["lfg"].theta["sigma"],
            "seconds": round(time.perf_counter() - t0, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fixtures", type=int, default=50)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--p-a", default="0.3,0.7")
    ap.add_argument("--roles", default="leader,follower")
    ap.add_argument("--noise-m", type=float, default=0.05)
    ap.add_argument("--window", type=int, default=11,
                    help="the Savitzky-Golay window [samples] (the pipeline's default: 11)")
    ap.add_argument("--model-smoothing", action="store_true",
                    help="the models' accelerations through the pipeline's smoothing too")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None, help="append one JSON line per fixture")
    args = ap.parse_args()
    grid = [(float(p), r) for p in args.p_a.split(",") for r in args.roles.split(",")]
    tasks = [(d, args.runs, *grid[d % len(grid)], args.noise_m, args.window,
              args.model_smoothing) for d in range(args.fixtures)]
    print(f"{args.fixtures} fixtures of {args.runs} runs, noise U(-{args.noise_m:g}, "
          f"{args.noise_m:g}) m, smoothing window {args.window}"
          f"{' (the models too)' if args.model_smoothing else ''}, settings (p_a, role) {grid}, "
          f"{args.workers} workers",
          flush=True)
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
    print(f"{n} fixtures in {time.perf_counter() - t0:.0f} s: coverage of the 95 % interval "
          f"{100 * cover:.0f} % ({sum(r['covered'] for r in rows)} of {n}; target 90-99 %), "
          f"BIC selects lfg in {100 * select:.0f} % (target >= 90 %); MAE {mae:.3f}, mean "
          f"interval width {width:.3f}")
    for (p, role) in grid:
        rs = [r for r in rows if r["p_a"] == p and r["role"] == role]
        if rs:
            print(f"  p_a {p:g}, {role}: {len(rs)} fixtures, coverage "
                  f"{100 * np.mean([r['covered'] for r in rs]):.0f} %, selection "
                  f"{100 * np.mean([r['selected'] == 'lfg' for r in rs]):.0f} %, mean "
                  f"estimate {np.mean([r['p_hat'] for r in rs]):.3f}")


if __name__ == "__main__":
    main()
