"""``persuasive recordings``: real drivers from recorded tracks (docs/guide/recordings.md).

- ``recordings pairs PATHS...``: read INTERACTION / inD track files, find the crossing and
  merging pairs, print a summary; ``--out FILE.parquet`` writes one row per pair and step,
  ``--figure FILE --pair ID`` draws one pair from above;
- ``recordings logs PAIRS.parquet --out DIR``: each pair from each driver's view as a log
  ``persuasive fit`` reads;
- ``recordings export RUNS... --out DIR``: ``simulate --out`` runs, or SUMO's floating-car
  data (``--fcd-output`` XML files), as INTERACTION track files;
- ``recordings replay PAIRS.parquet``: the AV in each recorded driver's seat, against the
  other driver replayed or a model fitted on the other recordings.

Every input and output is checked before any work; bad input ends the command with one line
(``error: ...``) and exit status 2, nothing written. Files are written atomically, folders as
a whole; ``--force`` replaces only the files of the names a folder command writes
(:data:`LOGS_FILES`, :data:`EXPORT_FILES`) and keeps every other file. A second command
writing the same output meanwhile is refused (:func:`persuasive.cli._common.lock_output`).
"""

from __future__ import annotations

import json
import math

import click

from ..config import AV_KINDS, MODES, SHIELD_KINDS, ConfigError
from ._common import check_workers, compile_notice, lock_output, progress_bar, workers_type

#: The files ``recordings logs`` writes (``<kind>-<angle>-p<pair>-hv<1|2>.parquet``).
LOGS_FILES = ("*-p*-hv[12].parquet",)
#: The files ``recordings export`` writes.
EXPORT_FILES = ("vehicle_tracks_*.csv", "vehicle_ids_*.csv", "map.osm")


class _BadInput(click.ClickException):
    """Bad input: one line, exit status 2 (through ``persuasive.cli.main`` and click's own
    runner alike)."""

    exit_code = 2


def _guard(call, *args, **kwargs):
    """``call(*args, **kwargs)`` with a bad recording or configuration as :class:`_BadInput`."""
    from ..recordings.formats import RecordingError

    try:
        return call(*args, **kwargs)
    except (RecordingError, ConfigError) as exc:
        raise _BadInput(str(exc)) from None


def _smoothing_options(func):
    """``--speed-from`` and ``--window``: the tracks' smoothing (``SmoothingParams``), shared
    by every command that reads track files."""
    for option in reversed([
        click.option("--speed-from", "speed_from", default="file", show_default=True,
                     metavar="SOURCE",
                     help="Speed and acceleration from the files' velocities, smoothed "
                          "('file'), or from the smoothed positions' derivatives "
                          "('positions')."),
        click.option("--window", type=int, default=7, show_default=True, metavar="SAMPLES",
                     help="The Savitzky-Golay filter's window (odd, at least 3; 7 = 0.6 s "
                          "at 10 Hz)."),
    ]):
        func = option(func)
    return func


@click.group()
def recordings() -> None:
    """Real drivers from recorded tracks (INTERACTION, inD): crossing pairs, fit logs, the AV in
    a recorded driver's seat, and our runs and SUMO's in their format."""


def _fmt(x: float | None, unit: str = "") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2f}{unit}"


def _print_summary(info: dict) -> None:
    click.echo(f"{info['vehicle_tracks']} vehicle tracks in {info['recordings']} recording"
               f"{'s' * (info['recordings'] != 1)}; {info['candidates']} candidate pairs "
               "compared")
    click.echo(f"pairs found: {info['pairs']} ({info['crossing']} crossing, {info['merge']} "
               "merge)")
    if info["angle_histogram"]:
        click.echo("crossing angles [deg]: " + ", ".join(
            f"{k}: {v}" for k, v in info["angle_histogram"].items()))
    if info["merge_angle_median_deg"] is not None:
        click.echo(f"merge angles: median {info['merge_angle_median_deg']:.1f} deg")
    for key, label in (("pet_area", "PET at the conflict area (pet_area_s)"),
                       ("pet", "PET on the occupancy intervals (pet_s)")):
        q = info[f"{key}_quantiles_s"]
        if q:
            click.echo(f"{label} [s] over {info[f'{key}_defined']} pairs: " + ", ".join(
                f"{k} {v:.2f}" for k, v in q.items()))
        else:
            click.echo(f"{label}: defined for no pair")
    first = info["first"]
    click.echo("first through the conflict point: " + ", ".join(
        f"{('vehicle ' + k) if k in ('1', '2') else k} {v}" for k, v in first.items()))
    click.echo(f"second passer slowed (speed drop >= the stated threshold): "
               f"{info['second_slowed']} of {info['second_known']}")
    if set(info["control"]) != {"unknown"}:
        click.echo("the map's rule: " + ", ".join(
            f"{k.replace('_', ' ')} {v}" for k, v in info["control"].items()))


@recordings.command("pairs")
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the pairs (.parquet): one row per pair and 10 Hz step.")
@click.option("--figure", type=click.Path(dir_okay=False), default=None,
              help="Draw pair --pair from above (.png, .svg, .pdf).")
@click.option("--pair", "pair_id", type=int, default=None, help="The pair --figure draws.")
@click.option("--angle-min", type=float, default=20.0, show_default=True, metavar="DEG",
              help="Smallest crossing angle kept (0: same direction, 180: head on).")
@click.option("--angle-max", type=float, default=160.0, show_default=True, metavar="DEG",
              help="Largest crossing angle kept.")
@click.option("--near-m", type=float, default=40.0, show_default=True, metavar="M",
              help="Both vehicles within this of the conflict point at one time.")
@_smoothing_options
@click.option("--map", "map_path", type=click.Path(dir_okay=False), default=None,
              metavar="FILE.osm",
              help="Lanelet2 map of the recordings' site: each pair's rule (right of way, "
                   "all-way stop) from it (needs the lanelet2 package: persuasive[maps]).")
@click.option("--map-origin", default="0,0", show_default=True, metavar="LAT,LON",
              help="The map's projection origin [deg] (INTERACTION: 0,0; inD: the "
                   "recording's latLocation,lonLocation).")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes, one track file each at a time [all cores, at most the "
                   "files]; the pairs do not depend on it.")
@click.option("--quiet", is_flag=True, help="No progress bar over the files.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
def pairs_command(paths, out, figure, pair_id, angle_min, angle_max, near_m, speed_from,
                  window, map_path, map_origin, workers, quiet, as_json) -> None:
    """Find the crossing and merging pairs of recorded tracks (files or folders of
    INTERACTION vehicle_tracks_NNN.csv, inD NN_tracks.csv with NN_tracksMeta.csv)."""
    from .._files import check_output_file
    from ..recordings.formats import find_track_files
    from ..recordings.pairs import PairParams
    from ..recordings.streaming import pair_and_tracks, site_pairs
    from ..recordings.tracks import SPEED_SOURCES, SmoothingParams

    if speed_from not in SPEED_SOURCES:
        raise _BadInput(f"--speed-from = {speed_from!r} is not allowed; allowed: "
                        f"{', '.join(SPEED_SOURCES)}")
    if out:
        _guard(check_output_file, out, (".parquet",), "pairs")
    if (figure is None) != (pair_id is None):
        raise _BadInput("--figure and --pair go together: --figure FILE --pair ID draws one "
                        "pair")
    if figure:
        from ..plots.files import check_figure_path

        _guard(check_figure_path, figure)
    for path, what in ((out, "pairs"), (figure, "figure")):
        if path:
            _guard(lock_output, path, what)
    params = _guard(PairParams, angle_range_deg=(angle_min, angle_max), near_m=near_m)
    smoothing = _guard(SmoothingParams, window=window, speed=speed_from)
    road_map = None
    if map_path is not None:
        from ..recordings.lanelet_map import read_map

        try:
            origin = [float(v) for v in map_origin.split(",")]
        except ValueError:
            raise _BadInput(f"--map-origin = {map_origin!r} is out of range; allowed: LAT,LON "
                            "in degrees") from None
        road_map = (str(map_path), tuple(_guard(read_map, map_path, origin).origin))
    files = _guard(find_track_files, paths)
    workers = check_workers(workers, len(files))
    bar = progress_bar(quiet or len(files) < 2, unit="file")
    try:
        site = _guard(site_pairs, paths, params, smoothing, road_map, out, workers, bar,
                      pair_id if figure else None)
    finally:
        if bar is not None:
            bar.close()  # type: ignore[attr-defined]
    info = site.summary
    if not info["pairs"]:
        raise _BadInput(f"no crossing pair: {info['vehicle_tracks']} vehicle tracks, "
                        f"{info['candidates']} candidate pairs, none crossing at "
                        f"[{angle_min:g}, {angle_max:g}] deg or merging with both approaching "
                        f"within {near_m:g} m at one time")
    if figure:
        from ..plots.files import save_figure
        from ..plots.recordings import pair_figure

        chosen, tracks = _guard(pair_and_tracks, site, files, pair_id, params, smoothing,
                                road_map)
        save_figure(pair_figure(chosen, tracks), figure)
    if as_json:
        click.echo(json.dumps(info))
        return
    _print_summary(info)
    written = [w for w in (out, figure) if w]
    if written:
        click.echo(f"written: {', '.join(written)}")


@recordings.command("logs")
@click.argument("pairs_file", type=click.Path(dir_okay=False))
@click.option("--out", type=click.Path(file_okay=False), required=True,
              help="Folder of the logs (written as a whole).")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier logs in the folder "
                   "(<kind>-<angle>-p<pair>-hv<1|2>.parquet); other files are kept.")
@click.option("--mode", type=click.Choice(list(MODES)), default="corrected",
              show_default=True, help="The logs' configuration mode (docs/method.md §9).")
@click.option("--angle-step", type=float, default=5.0, show_default=True, metavar="DEG",
              help="Round each pair's angle to a multiple of this (0: keep it), so that "
                   "pairs at nearly one angle share a scenario and fit together.")
def logs_command(pairs_file, out, force, mode, angle_step) -> None:
    """Write each pair, from each driver's view, as a log 'persuasive fit' reads."""
    from .._files import atomic_folder, check_replaceable_folder
    from ..config import Config
    from ..recordings.logs import groups, write_logs
    from ..recordings.pairs import read_pairs

    if not (math.isfinite(angle_step) and 0.0 <= angle_step <= 45.0):
        raise _BadInput(f"--angle-step = {angle_step:g} is out of range; allowed: [0, 45] "
                        "degrees")
    _guard(check_replaceable_folder, out, force, "logs folder", LOGS_FILES)
    _guard(lock_output, out, "logs folder")
    frame, _ = _guard(read_pairs, pairs_file)
    base = Config(mode=mode)
    with atomic_folder(out, "logs folder", LOGS_FILES) as tmp:
        written = _guard(write_logs, frame, tmp, base, angle_step)
    n_pairs = len({w.pair for w in written})
    click.echo(f"{len(written)} logs of {n_pairs} pairs (each driver's view) in {out}")
    for (kind, angle), items in groups(written).items():
        steps = sum(w.n_steps for w in items)
        click.echo(f"  {kind} at {angle:g} deg: {len(items)} logs, {steps} steps; fit with: "
                   f"persuasive fit {out}/{kind}-{angle:g}-*.parquet")


@recordings.command("export")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--out", type=click.Path(file_okay=False), required=True,
              help="Folder of the track files (written as a whole).")
@click.option("--noise-m", type=float, default=0.0, show_default=True, metavar="M",
              help="Half-width of the uniform noise added to x and to y [m].")
@click.option("--noise-mps", type=float, default=0.0, show_default=True, metavar="M/S",
              help="Half-width of the uniform noise added to the speed (vx, vy) [m/s].")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the noise.")
@click.option("--types", "types", multiple=True, type=click.Path(dir_okay=False),
              metavar="FILE", help="SUMO route or additional file whose vType elements give "
                                   "the vehicles' lengths and widths (fcd input only; "
                                   "repeatable).")
@click.option("--map-rule", "map_rule", default=None, metavar="RULE",
              help="Also write map.osm, the runs' scenario as a Lanelet2 map with this rule: "
                   "'av' or 'hv' (who has the right of way), 'all-way-stop' (runs only; needs "
                   "persuasive[maps]).")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier files in the folder "
                   "(vehicle_tracks_*.csv, vehicle_ids_*.csv, map.osm); other files are kept.")
def export_command(inputs, out, noise_m, noise_mps, seed, types, map_rule, force) -> None:
    """Write simulate --out runs (.parquet; track 1 the AV, track 2 the HV) or SUMO
    --fcd-output files (.xml) as INTERACTION track files, vehicle_tracks_NNN.csv, one per
    input."""
    from .._files import atomic_folder, check_replaceable_folder
    from ..recordings.export import export_fcd, export_runs

    if not (math.isfinite(noise_m) and noise_m >= 0.0):
        raise _BadInput(f"--noise-m = {noise_m:g} is out of range; allowed: a number >= 0 m")
    if not (math.isfinite(noise_mps) and noise_mps >= 0.0):
        raise _BadInput(f"--noise-mps = {noise_mps:g} is out of range; allowed: a number "
                        ">= 0 m/s")
    fcd = [str(p).lower().endswith(".xml") for p in inputs]
    if any(fcd) and not all(fcd):
        raise _BadInput("give simulate --out runs (.parquet) or SUMO fcd files (.xml), not "
                        "both in one export")
    if types and not all(fcd):
        raise _BadInput("--types is read with SUMO fcd files (.xml) only")
    from ..recordings.lanelet_map import MAP_RULES

    if map_rule is not None and map_rule not in MAP_RULES:
        raise _BadInput(f"--map-rule = {map_rule!r} is not allowed; allowed: "
                        f"{', '.join(MAP_RULES)}")
    if map_rule is not None and all(fcd):
        raise _BadInput("--map-rule is written for simulate --out runs (.parquet) only")
    _guard(check_replaceable_folder, out, force, "tracks folder", EXPORT_FILES)
    _guard(lock_output, out, "tracks folder")
    # every input is read before anything is written; a failure removes the temporary folder
    with atomic_folder(out, "tracks folder", EXPORT_FILES) as tmp:
        if all(fcd):
            names = _guard(export_fcd, inputs, tmp, noise_m, seed, types, noise_mps)
        else:
            names = _guard(export_runs, inputs, tmp, noise_m, seed, noise_mps, map_rule)
    what = ", from SUMO fcd" if all(fcd) else ""
    speed = f", U(-{noise_mps:g}, {noise_mps:g}) m/s on the speed" if noise_mps else ""
    tracks = [n for n in names if n.endswith(".csv")]
    drawn = f"; the map ({map_rule}) in map.osm" if map_rule else ""
    click.echo(f"{len(tracks)} track file{'s' * (len(tracks) != 1)} (INTERACTION format{what}, "
               f"noise U(-{noise_m:g}, {noise_m:g}) m{speed}, seed {seed}) in {out}{drawn}")


def _print_replay(info: dict, runs: list) -> None:
    c = info["collisions"]
    other = "the recorded driver replayed" if info["other"] == "replay" else \
        f"the {info['model']} model fitted on the other recordings"
    click.echo(f"{info['runs']} runs of {info['pairs']} pairs: AV {info['av']} with shield "
               f"{info['shield']} in a recorded driver's seat, the other vehicle {other}")
    sel = info.get("selection") or {}
    if sel:
        left = sum(sel["left_out"].values())
        bound = "every pair" if sel["pet_area_max_s"] is None else \
            f"PET at the conflict area at most {sel['pet_area_max_s']:g} s, or unknown"
        click.echo(f"pairs replayed: {sel['replayed']} of {sel['pairs']} ({bound}; "
                   f"{sel['unknown_pet']} without a PET at the area); left out: {left}"
                   + "".join(f", {n} with {why} (no interaction)"
                             for why, n in sel["left_out"].items())
                   + ("; --pet-max inf replays every pair" if left else ""))
    if info.get("human_envelope", "paper") != "paper":
        from ..config import HUMAN_ENVELOPES

        u_min, u_max, v_max, _ = HUMAN_ENVELOPES[info["human_envelope"]]
        click.echo(f"the shield's human envelope: {info['human_envelope']} (u in [{u_min:g}, "
                   f"{u_max:g}] m/s^2, v <= {v_max:.4g} m/s)")
    click.echo(f"collisions: {c['collisions']} of {c['runs']} runs (AV-caused "
               f"{c['av_caused']}, rear-end by the human {c['rear_end_by_human']})")
    for key, label in (("within_envelope_certified_start", "driver within the envelope, start "
                        "certified"),
                       ("beyond_envelope", "driver beyond the envelope"),
                       ("uncertified_start", "start not certified")):
        g = info[key]
        click.echo(f"  {label}: {g['runs']} runs, {g['collisions']} collisions, "
                   f"{g['av_caused']} AV-caused")
    click.echo(f"shield: {info['uncertified_steps']} uncertified steps in "
               f"{info['runs_with_uncertified_steps']} runs; guarantee held in "
               f"{info['guarantee_held']} of {info['runs']} runs")
    row = info["right_of_way"]
    if row["av"] or row["hv"]:
        click.echo(f"the map's right of way: the AV's in {row['av']} runs, the other's in "
                   f"{row['hv']}, neither in {row['neither']} (the responsibility shield reads "
                   "it)")
    e = info["envelope"]
    if runs:
        lo, hi = runs[0].u_min_mps2, runs[0].u_max_mps2
        share = 100.0 * (e["excess_share"] or 0.0)
        click.echo(f"envelope (u in [{lo:g}, {hi:g}] m/s^2): {e['excess_steps']} of "
                   f"{e['steps']} recorded steps beyond ({share:.1f} %), in "
                   f"{e['runs_beyond']} of {info['runs']} runs; accelerations "
                   f"{e['accel_min_mps2']:.2f} to {e['accel_max_mps2']:.2f} m/s^2")
    from ..recordings.envelope import short

    premise = info.get("premise_by_envelope") or {}
    if premise:
        click.echo("premise held (the driver within the envelope on every tested step, the "
                   "start certified), by envelope:")
    for name, p in premise.items():
        if name == "configured":
            bounds = (f"u in [{runs[0].u_min_mps2:g}, {runs[0].u_max_mps2:g}] m/s^2, v up to "
                      "the pair's highest speed" if runs else "the runs' own")
        else:
            v = f", v <= {short(p['v_max_mps'])} m/s" if p["v_max_mps"] is not None else ""
            bounds = f"u in [{short(p['u_min_mps2'])}, {short(p['u_max_mps2'])}] m/s^2{v}"
        share = f" ({100.0 * p['share']:.1f} %)" if p["share"] is not None else ""
        click.echo(f"  {name} ({bounds}): {p['runs']} of {info['runs']} runs{share}; driver "
                   f"within in {p['within_envelope']}")
    invalid = sum(info["invalid"].values())
    if info["other"] == "replay":
        detail = ", ".join(f"{k} {v}" for k, v in sorted(info["invalid"].items()))
        click.echo(f"invalid runs: {invalid}{' (' + detail + ')' if detail else ''}; rule: "
                   "the replayed driver passed after the replaced vehicle and the AV did not "
                   "pass first (yielded), or it drove into the AV from behind (rear-end)")
    first = ", ".join(f"{k} {v}" for k, v in sorted(info["first_replay"].items()))
    rec = ", ".join(f"{k} {v}" for k, v in sorted(info["first_recorded"].items()))
    click.echo(f"valid runs: {info['valid']}; first through the conflict point: {first or '-'} "
               f"(recorded: {rec or '-'})")
    diff = info["clear_s_paired_diff_mean"]
    click.echo(f"time to clear, restricted mean over the valid runs: AV "
               f"{_fmt(info['av_clear_s_rmean'], ' s')}, recorded driver "
               f"{_fmt(info['recorded_clear_s_rmean'], ' s')}; AV minus recorded where both "
               f"cleared ({info['both_cleared']} runs): {_fmt(diff, ' s')}")


@recordings.command("replay")
@click.argument("pairs_file", type=click.Path(dir_okay=False))
@click.option("--av", default="persuasive", show_default=True, metavar="KIND",
              help=f"The AV's planner: {', '.join(AV_KINDS)}.")
@click.option("--shield", default="worst-case", show_default=True, metavar="KIND",
              help=f"The AV's shield: {', '.join(SHIELD_KINDS)}.")
@click.option("--other", default="replay", show_default=True, metavar="KIND",
              help="The other vehicle: replay (the recorded driver, open loop) or fitted "
                   "(a human model fitted on the pairs of the other recordings).")
@click.option("--model", default=None, metavar="MODEL",
              help="The fitted model with --other fitted: lfg (default), stubborn, noisy, "
                   "idm.")
@click.option("--seat", type=click.Choice(["1", "2", "both"]), default="both",
              show_default=True, help="The vehicle whose place the AV takes.")
@click.option("--extra-s", type=float, default=10.0, show_default=True, metavar="S",
              help="Run on this long after the recording ends.")
@click.option("--mode", type=click.Choice(list(MODES)), default="corrected",
              show_default=True, help="The configuration mode (docs/method.md §9).")
@click.option("--angle-step", type=float, default=5.0, show_default=True, metavar="DEG",
              help="Round each pair's angle to a multiple of this (as recordings logs).")
@click.option("--envelope", default="paper", show_default=True, metavar="NAME",
              help="The human envelope the shield assumes of the other vehicle and the "
                   "premise tests the recorded driver against: paper (the configuration's), "
                   "sumo or real-driver (hv.envelope).")
@click.option("--pet-max", "pet_max", type=float, default=4.0, show_default=True,
              metavar="S",
              help="Replay the pairs that interact: PET at the conflict area (pet_area_s) "
                   "at most S seconds, or unknown; the others are counted as left out. inf: "
                   "every pair.")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write one row per run (.parquet or .csv).")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes [all cores]; the runs do not depend on it.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
def replay_command(pairs_file, av, shield, other, model, seat, extra_s, mode, angle_step,
                   envelope, pet_max, out, workers, quiet, as_json) -> None:
    """Put the AV in each recorded driver's seat at the start of each pair: collisions, the
    shield's uncertified steps, the recorded driver against the shield's envelope, who passed
    first and the time to clear against the recorded driver's own."""
    from .._files import atomic_write, check_output_file
    from ..config import Config
    from ..recordings.pairs import read_pairs
    from ..recordings.replay import ReplaySettings, replay_pairs

    if model is not None and other != "fitted":
        raise _BadInput(f"--model {model} is read with --other fitted only")
    if not (math.isfinite(angle_step) and 0.0 <= angle_step <= 45.0):
        raise _BadInput(f"--angle-step = {angle_step:g} is out of range; allowed: [0, 45] "
                        "degrees")
    seats = (1, 2) if seat == "both" else (int(seat),)
    settings = _guard(ReplaySettings, av=av, shield=shield, other=other,
                      model=model or "lfg", extra_s=extra_s, seats=seats, mode=mode,
                      angle_step_deg=angle_step, envelope=envelope, pet_area_max_s=pet_max)
    if out:
        _guard(check_output_file, out, (".parquet", ".csv"), "replay table")
        _guard(lock_output, out, "replay table")
    frame, _ = _guard(read_pairs, pairs_file)
    n_pairs = int(frame["pair"].nunique()) if len(frame) else 0
    workers = check_workers(workers, max(1, n_pairs // 25))
    compile_notice()
    bar = progress_bar(quiet, unit="pair")
    try:
        result = _guard(replay_pairs, frame, settings, Config(mode=mode), str(pairs_file),
                        workers, bar)
    finally:
        if bar is not None:
            bar.close()  # type: ignore[attr-defined]
    if out:
        table = result.frame()
        write = (lambda p: table.to_parquet(p, index=False)) if out.lower().endswith(
            ".parquet") else (lambda p: table.to_csv(p, index=False))
        _guard(atomic_write, out, write)
    info = result.summary()
    if as_json:
        click.echo(json.dumps({**info, "fits": result.fits}))
        return
    _print_replay(info, result.runs)
    for rec, params in result.fits.items():
        click.echo(f"  fitted without {rec}: " + ", ".join(
            f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in params.items()))
    if out:
        click.echo(f"written: {out}")


def _pct(share: float | None) -> str:
    return "-" if share is None else f"{100.0 * share:.2f} %"


def _print_envelope(result, info: dict, quantile: float) -> None:
    from ..recordings.envelope import QUANTILES, VEHICLES
    from ..recordings.formats import VEHICLE_CLASSES

    files = len(info["files"])
    click.echo(f"{files} recording file{'s' * (files != 1)}; steps from the smoothed speeds "
               f"(window {result.smoothing.window}, speed from the {result.smoothing.speed}), "
               f"those reading a track's first or last {result.edge_samples} samples left out")
    names = [name for name, _ in QUANTILES] + ["max"]
    kinds = [g for g in info["classes"] if g in VEHICLE_CLASSES]
    groups = {g: c for g, c in info["classes"].items() if g != VEHICLES or len(kinds) > 1}
    for group, c in groups.items():
        what = "the vehicle classes pooled" if group == VEHICLES else "class"
        click.echo(f"{group} ({what}): {c['tracks']} tracks ({c['short_tracks']} shorter than "
                   f"{result.smoothing.min_track_s:g} s left out), {c['steps']} steps tested "
                   f"({c['edge_steps']} at the tracks' ends left out)")
        if not c["steps"]:
            continue
        click.echo(f"| {group} | " + " | ".join(names) + f" | q = {quantile:g} |")
        click.echo("|---" * (len(names) + 2) + "|")
        for key, label in (("speed_mps", "speed [m/s]"), ("accel_mps2", "acceleration [m/s^2]"),
                           ("braking_mps2", "braking [m/s^2]")):
            row = [_fmt(c[key][n]) for n in names] + [_fmt(c["at_quantile"][key])]
            click.echo(f"| {label} | " + " | ".join(row) + " |")
    click.echo("steps beyond each envelope (braking below u_min, acceleration above u_max or "
               "speed above v_max; a step can count on two sides):")
    click.echo("| envelope | bounds | class | steps beyond | share | braking | acceleration | "
               "speed | tracks beyond |")
    click.echo("|---" * 9 + "|")
    for env in result.envelopes:
        for group, c in groups.items():
            if not c["steps"]:
                continue
            b = c["beyond"][env.name]
            click.echo(f"| {env.name} | {env.text()} | {group} | {b['steps']} of {c['steps']} | "
                       f"{_pct(b['share'])} | {b['braking']} | {b['acceleration']} | "
                       f"{b['speed']} | {b['tracks']} of {c['tracks']} |")
    click.echo("sources:")
    for env in result.envelopes:
        click.echo(f"  {env.name}: {env.source}")
    est = info["estimate"]
    pooled = "the vehicle classes" if len(kinds) > 1 else f"the {kinds[0]} class" \
        if kinds else "the vehicle classes"
    if est is None:
        click.echo(f"no envelope at q = {quantile:g}: no vehicle step tested, or a quantile "
                   "of 0")
    else:
        click.echo(f"the envelope of {pooled} at q = {quantile:g}, as configuration "
                   "overrides:")
        click.echo(est["toml"].rstrip("\n"))


@recordings.command("envelope")
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option("--quantile", type=float, default=0.999, show_default=True, metavar="Q",
              help="The quantile of the estimated envelope, in (0, 1).")
@click.option("--bound", "bounds", multiple=True, metavar="U_MIN,U_MAX[,V_MAX]",
              help="A candidate envelope of your own [m/s^2, m/s] (repeatable), tested beside "
                   "the named ones (no V_MAX: the speed is not bounded).")
@click.option("--types", "types", multiple=True, type=click.Path(dir_okay=False),
              metavar="FILE", help="SUMO route or additional file whose vType elements the "
                                   "fcd files' vehicles use (fcd input only; repeatable).")
@_smoothing_options
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the whole result (.json).")
@click.option("--json", "as_json", is_flag=True, help="Print the whole result as one JSON "
                                                       "object.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def envelope_command(paths, quantile, bounds, types, speed_from, window, out, as_json,
                     quiet) -> None:
    """The human envelope of recorded drivers, per class: quantiles of their speed,
    acceleration and braking, and the share of steps beyond each named envelope (paper,
    sumo, real-driver) and each --bound (files or folders of INTERACTION
    vehicle_tracks_NNN.csv, inD NN_tracks.csv, SUMO fcd .xml)."""
    from .._files import atomic_write, check_output_file, json_safe
    from ..recordings.envelope import candidate_envelopes, estimate_envelope, recording_files
    from ..recordings.tracks import SPEED_SOURCES, SmoothingParams

    if not (math.isfinite(quantile) and 0.0 < quantile < 1.0):
        raise _BadInput(f"--quantile = {quantile:g} is out of range; allowed: (0, 1), e.g. "
                        "0.999")
    if speed_from not in SPEED_SOURCES:
        raise _BadInput(f"--speed-from = {speed_from!r} is not allowed; allowed: "
                        f"{', '.join(SPEED_SOURCES)}")
    envelopes = _guard(candidate_envelopes, bounds)
    smoothing = _guard(SmoothingParams, window=window, speed=speed_from)
    files = _guard(recording_files, paths)
    if types and not any(fmt == "fcd" for _, fmt in files):
        raise _BadInput("--types is read with SUMO fcd files (.xml) only")
    if out:
        _guard(check_output_file, out, (".json",), "envelope")
        _guard(lock_output, out, "envelope")
    progress = progress_bar(quiet, unit="file")
    try:
        result = _guard(estimate_envelope, paths, envelopes, smoothing, types, progress)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    info = json_safe(result.to_dict(quantile))
    if out:
        text = json.dumps(info, allow_nan=False, indent=1)
        _guard(atomic_write, out, lambda p: p.write_text(text + "\n", encoding="utf-8"))
    if as_json:
        click.echo(json.dumps(info, allow_nan=False))
        return
    _print_envelope(result, info, quantile)
    if out:
        click.echo(f"written: {out}")


__all__ = ["envelope_command", "export_command", "logs_command", "pairs_command",
           "recordings", "replay_command"]
