"""``persuasive recordings``: real drivers from recorded tracks (docs/guide/recordings.md).

- ``recordings pairs PATHS...``: read INTERACTION / inD track files, find the crossing and
  merging pairs, print a summary; ``--out FILE.parquet`` writes one row per pair and step,
  ``--figure FILE --pair ID`` draws one pair from above;
- ``recordings logs PAIRS.parquet --out DIR``: each pair from each driver's view as a log
  ``persuasive fit`` reads;
- ``recordings export RUNS... --out DIR``: ``simulate --out`` runs as INTERACTION track files.

Every input and output is checked before any work; bad input ends the command with one line
(``error: ...``) and exit status 2, nothing written. Files are written atomically, folders as
a whole.
"""

from __future__ import annotations

import json
import math

import click

from ..config import MODES, ConfigError


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


@click.group()
def recordings() -> None:
    """Real drivers from recorded tracks (INTERACTION, inD): crossing pairs, fit logs, and our
    runs in their format."""


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
    q = info["pet_quantiles_s"]
    if q:
        click.echo(f"PET [s] over {info['pet_defined']} pairs: " + ", ".join(
            f"{k} {v:.2f}" for k, v in q.items()))
    else:
        click.echo("PET: defined for no pair")
    first = info["first"]
    click.echo("first through the conflict point: " + ", ".join(
        f"{('vehicle ' + k) if k in ('1', '2') else k} {v}" for k, v in first.items()))
    click.echo(f"second passer slowed (speed drop >= the stated threshold): "
               f"{info['second_slowed']} of {info['second_known']}")


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
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
def pairs_command(paths, out, figure, pair_id, angle_min, angle_max, near_m, as_json) -> None:
    """Find the crossing and merging pairs of recorded tracks (files or folders of
    INTERACTION vehicle_tracks_NNN.csv, inD NN_tracks.csv with NN_tracksMeta.csv)."""
    from .._files import check_output_file
    from ..recordings.formats import read_tracks
    from ..recordings.pairs import PairParams, find_pairs, pair_of, summary, write_pairs
    from ..recordings.tracks import smooth_tracks

    if out:
        _guard(check_output_file, out, (".parquet",), "pairs")
    if (figure is None) != (pair_id is None):
        raise _BadInput("--figure and --pair go together: --figure FILE --pair ID draws one "
                        "pair")
    if figure:
        from ..plots.files import check_figure_path

        _guard(check_figure_path, figure)
    params = _guard(PairParams, angle_range_deg=(angle_min, angle_max), near_m=near_m)
    table = _guard(read_tracks, paths)
    result = _guard(find_pairs, _guard(smooth_tracks, table), params)
    if not result.pairs:
        raise _BadInput(f"no crossing pair: {result.tracks.n_tracks} vehicle tracks, "
                        f"{result.candidates} candidate pairs, none crossing at "
                        f"[{angle_min:g}, {angle_max:g}] deg or merging with both approaching "
                        f"within {near_m:g} m at one time")
    chosen = _guard(pair_of, result, pair_id) if figure else None
    if out:
        write_pairs(out, result, paths)
    if figure:
        from ..plots.files import save_figure
        from ..plots.recordings import pair_figure

        save_figure(pair_figure(chosen, result.tracks), figure)
    info = summary(result)
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
@click.option("--force", is_flag=True, help="Replace a folder that holds other files.")
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
    _guard(check_replaceable_folder, out, force, "logs folder")
    frame, _ = _guard(read_pairs, pairs_file)
    base = Config(mode=mode)
    with atomic_folder(out, "logs folder") as tmp:
        written = _guard(write_logs, frame, tmp, base, angle_step)
    n_pairs = len({w.pair for w in written})
    click.echo(f"{len(written)} logs of {n_pairs} pairs (each driver's view) in {out}")
    for (kind, angle), items in groups(written).items():
        steps = sum(w.n_steps for w in items)
        click.echo(f"  {kind} at {angle:g} deg: {len(items)} logs, {steps} steps; fit with: "
                   f"persuasive fit {out}/{kind}-{angle:g}-*.parquet")


@recordings.command("export")
@click.argument("runs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--out", type=click.Path(file_okay=False), required=True,
              help="Folder of the track files (written as a whole).")
@click.option("--noise-m", type=float, default=0.0, show_default=True, metavar="M",
              help="Half-width of the uniform noise added to x and to y [m].")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Seed of the noise.")
@click.option("--force", is_flag=True, help="Replace a folder that holds other files.")
def export_command(runs, out, noise_m, seed, force) -> None:
    """Write simulate --out runs as INTERACTION track files (vehicle_tracks_NNN.csv, one per
    run: track 1 the AV, track 2 the HV)."""
    from .._files import atomic_folder, check_replaceable_folder
    from ..recordings.export import export_runs

    if not (math.isfinite(noise_m) and noise_m >= 0.0):
        raise _BadInput(f"--noise-m = {noise_m:g} is out of range; allowed: a number >= 0 m")
    _guard(check_replaceable_folder, out, force, "tracks folder")
    # every run is read before anything is written; a failure removes the temporary folder
    with atomic_folder(out, "tracks folder") as tmp:
        names = _guard(export_runs, runs, tmp, noise_m, seed)
    click.echo(f"{len(names)} track file{'s' * (len(names) != 1)} (INTERACTION format, noise "
               f"U(-{noise_m:g}, {noise_m:g}) m, seed {seed}) in {out}")


__all__ = ["export_command", "logs_command", "pairs_command", "recordings"]
