"""How fast every human model is fitted to recorded pairs (issue 26's target: 2,500 pairs in
under 60 s; docs/guide/recordings.md, "Speed").

    python benchmarks/fit_pairs_speed.py [--pairs 2500] [--files 2] [--tracks 600] [--repeat 3]
                                         [--intervals] [--per-model] [--logs]

Writes the synthetic INTERACTION folder of ``benchmarks/recordings_speed.py`` (``--files``
recordings of ``--tracks`` tracks each, a busy four-arm junction, 5 cm of position noise),
reads, smooths and pairs it, keeps the first ``--pairs`` pairs (in order of recording and
time), and times what ``persuasive fit`` does with them before it scores anything: both views
of every pair as runs (``persuasive.recordings.evaluate.ViewBuilder``, the vehicle limits from
the pairs' 1 %/99 % acceleration quantiles) and their scenarios' geometry (which an evaluation
builds once for all its folds, ``persuasive.record.scenario_of``; cleared before each run),
their evidence (``persuasive.fitting.evidence_of``: every view's games solved in its own
scenario, in every fold) and the fit of every model
(``persuasive.fitting.fit_models``: ``lfg``, ``stubborn``, ``noisy``, ``idm``; point estimates,
or with ``--intervals`` the profile intervals too). Prints the median of ``--repeat`` runs in
one process, after one untimed run that compiles and caches the kernels, and the steps fitted.
``--per-model``: also each model fitted alone, once (the ``noisy`` human's time includes the
``lfg`` fit it starts from). ``--logs``: the views as ``recordings logs`` writes them, the
tracks' filter in their metadata, so that the fit's measurement model is on (the ``lfg`` and
``stubborn`` over role paths, ``persuasive.fitting.models.path_loglik``).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import tempfile
import time
from pathlib import Path


def synthetic_folder():
    """``write_folder`` of ``benchmarks/recordings_speed.py`` (one writer of the folder)."""
    path = Path(__file__).with_name("recordings_speed.py")
    spec = importlib.util.spec_from_file_location("recordings_speed", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.write_folder


def recorded_views(pairs):
    """Both views of every pair as ``recordings logs`` writes them: with the tracks' filter in
    their metadata, so that the fit scores them through its measurement model (the ``lfg``
    and ``stubborn`` over role paths). ``pairs``: ``(frame rows, smoothing)`` per pair."""
    from persuasive import Config
    from persuasive.fitting.evidence import RunLog
    from persuasive.recordings.logs import view_log

    base = Config(mode="corrected")
    out = []
    for rows, smoothing in pairs:
        for h in (1, 2):
            config, log, meta = view_log(rows, h, base, smoothing=smoothing)
            states = log[["av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m",
                          "hv_meas_v_mps"]].to_numpy(float)
            out.append(RunLog(f"pair {meta['seed']} hv{h}", config, int(meta["seed"]), None,
                              states, log["hv_accel_mps2"].to_numpy(float), meta))
    return out


def views_of(pairs):
    """The runs a fit of ``pairs`` scores: the held-out evaluation's views
    (``ViewBuilder``; no measurement model), or :func:`recorded_views` for ``--logs``."""
    from persuasive.recordings.evaluate import ViewBuilder, speed_cap, vehicle_limits

    if pairs and isinstance(pairs[0], tuple):
        return recorded_views(pairs)
    builder = ViewBuilder("corrected", vehicle_limits(pairs, 0.01), speed_cap(pairs, 10.0))
    return [builder.view(p, h) for p in pairs for h in (1, 2)]


def fit_once(pairs, intervals: bool) -> tuple[float, float, float, int, dict]:
    """The views and their scenarios' geometry (none kept from before: what an evaluation
    builds once, ``persuasive.record.GEOMETRIES``), their evidence (every fold's games, the
    geometry kept), then the fits: ``(seconds to geometry, to evidence, to fit, steps,
    BIC)``."""
    from persuasive.fitting import evidence_of, fit_models
    from persuasive.fitting.comparison import MODELS
    from persuasive.record import GEOMETRIES, scenario_of, static_setup

    GEOMETRIES.clear()
    static_setup.cache_clear()
    t0 = time.perf_counter()
    views = views_of(pairs)
    for view in views:
        scenario_of(view.config)
    t1 = time.perf_counter()
    ev = evidence_of(views)
    t2 = time.perf_counter()
    report = fit_models(ev, list(MODELS), intervals=intervals)
    t3 = time.perf_counter()
    return (t1 - t0, t2 - t1, t3 - t2, int(ev.accel.shape[0]),
            {m: f.bic for m, f in report.fits.items()})


def per_model(pairs, intervals: bool) -> dict[str, float]:
    """Seconds to fit each model alone to the pairs' evidence."""
    from persuasive.fitting import evidence_of, fit_models
    from persuasive.fitting.comparison import MODELS

    ev = evidence_of(views_of(pairs))
    out = {}
    for m in MODELS:
        t0 = time.perf_counter()
        fit_models(ev, [m], intervals=intervals)
        out[m] = time.perf_counter() - t0
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=2500)
    parser.add_argument("--files", type=int, default=2)
    parser.add_argument("--tracks", type=int, default=600, help="tracks per file")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--intervals", action="store_true")
    parser.add_argument("--per-model", action="store_true")
    parser.add_argument("--logs", action="store_true",
                        help="fit the views as recordings logs writes them (the fit's "
                             "measurement model on), not the held-out evaluation's")
    args = parser.parse_args()
    from persuasive.recordings.evaluate import pairs_of
    from persuasive.recordings.formats import read_tracks
    from persuasive.recordings.pairs import find_pairs, pairs_frame
    from persuasive.recordings.tracks import smooth_tracks

    with tempfile.TemporaryDirectory() as tmp:
        synthetic_folder()(Path(tmp), args.files, args.tracks)
        result = find_pairs(smooth_tracks(read_tracks([Path(tmp)])))
    frame = pairs_frame(result.pairs)
    pairs = pairs_of(frame, "synthetic", False)[:args.pairs]
    if args.logs:
        from dataclasses import asdict

        smoothing = asdict(result.tracks.params)
        keep = {p.pair for p in pairs}
        pairs = [(rows.sort_values("step"), smoothing)
                 for pair_id, rows in frame.groupby("pair", sort=True) if pair_id in keep]
    if len(pairs) < args.pairs:
        raise SystemExit(f"only {len(pairs)} pairs in {args.files} x {args.tracks} tracks: "
                         "raise --tracks or --files")
    fit_once(pairs[:20], args.intervals)  # compile and cache, untimed
    runs = [fit_once(pairs, args.intervals) for _ in range(args.repeat)]
    total = [g + e + f for g, e, f, _, _ in runs]
    what = "recorded logs, measurement model on" if args.logs else "the evaluation's views"
    print(f"{len(pairs)} pairs ({2 * len(pairs)} views: {what}; {runs[0][3]} steps), every model "
          f"{'with' if args.intervals else 'without'} intervals: median "
          f"{statistics.median(total):.1f} s of {args.repeat} "
          f"({', '.join(f'{t:.1f}' for t in total)}); the views and their geometry "
          f"{statistics.median(g for g, *_ in runs):.1f} s (once per evaluation), evidence "
          f"{statistics.median(e for _, e, *_ in runs):.1f} s and fits "
          f"{statistics.median(f for _, _, f, *_ in runs):.1f} s (per fold); "
          f"{os.cpu_count()} cores")
    print("BIC: " + ", ".join(f"{m} {b:.0f}" for m, b in runs[0][4].items()))
    if args.per_model:
        print("each model alone: " + ", ".join(f"{m} {t:.1f} s" for m, t in
                                               per_model(pairs, args.intervals).items()))


if __name__ == "__main__":
    main()
