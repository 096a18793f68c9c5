"""``persuasive sweep`` (a grid of configurations times seeds, on Dask) and ``persuasive plot
sweep`` (a metric of a sweep over one or two axes, with 95 % intervals)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from .._compile import StudyClock
from ._common import (Count, check_workers, compile_notice, compile_report, lock_output,
                      progress_bar, shield_option, workers_type)

#: Most runs in one chunk: a chunk's rows are held in one worker's memory until its part is
#: written (the default is at most 250).
MAX_CHUNK = 100_000

_GRID_HELP = """Run every run of a grid of configurations times seeds, on Dask.

\b
GRID.toml:
  seeds = 1000                 # seeds 1..1000, or [seeds] start = 1, stop = 1000
                               # (both ends inclusive)
  [base]                       # any configuration, as in a --config file
  simulation.n_steps = 61
  [axes]                       # dotted field = [values]; runs = product x seeds
  "roles.p_a" = [0.3, 0.7, 1.0]
  mode = ["paper", "corrected"]

The runs are written in chunks to OUT/runs/part-*.parquet (one row per run; read them with
persuasive.sweep.load(OUT) or pandas.read_parquet(OUT/runs)), failed runs to
OUT/failed/*.json. Rerunning the same command resumes: finished chunks are skipped and chunks
with failed runs are retried. A different grid into the same folder is refused unless
--force, which replaces only the sweep's own files (other files are kept). A second command
writing the same folder meanwhile is refused. Exit status 1 when a run failed, 2 for bad
input.
"""


def _default_out(grid_path: str, digest: str) -> Path:
    return Path("results") / f"sweep-{Path(grid_path).stem}-{digest[:10]}"


@click.command(help=_GRID_HELP)
@click.argument("grid_file", metavar="GRID.toml", type=click.Path(dir_okay=False))
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Sweep folder [results/sweep-<grid name>-<grid hash>/].")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes of the local Dask cluster [all cores; never more than "
                   "the chunks to run]. Not with --scheduler.")
@click.option("--scheduler", metavar="tcp://HOST:PORT", default=None,
              help="Use a running Dask scheduler (dask scheduler / dask worker) instead of "
                   "a local cluster.")
@click.option("--chunk", type=Count(1, MAX_CHUNK), default=None,
              help="Runs per chunk, one Parquet part each [about 32 chunks of 1 to 250 "
                   "runs; when resuming, the folder's].")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier results in the folder (another "
                   "sweep's manifest.json, runs/part-*.parquet, failed/failed-*.json); other "
                   "files are kept.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@shield_option
def sweep(grid_file, out, workers, scheduler, chunk, force, as_json, quiet, shield) -> None:
    from .. import sweep as sw
    from .._files import check_output_folder
    from ..config import ConfigError

    # validated whole before anything runs; --shield sets the base's av.shield
    grid = sw.Grid.from_toml(grid_file, {"av.shield": shield} if shield else None)
    if workers is not None and scheduler is not None:
        raise ConfigError("--workers applies to the local cluster only; the workers of "
                          "--scheduler are those started with 'dask worker'")
    folder = Path(out) if out else _default_out(grid_file, grid.digest)
    check_output_folder(folder, "sweep folder")
    lock_output(folder, "sweep folder")
    if scheduler is None:
        n_chunks = -(-len(grid) // (chunk or sw.store.default_chunk(len(grid))))
        workers = check_workers(workers, n_chunks)
        compile_notice()
    progress = progress_bar(quiet)
    clock = StudyClock()
    try:
        summary = sw.run(grid, folder, workers=workers, scheduler=scheduler, chunk=chunk,
                         force=force, progress=progress)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    # the sweep's own time: a first run's compile is said apart (compile_report)
    summary = replace(summary, wall_time_s=max(0.0, summary.wall_time_s - clock.compile_s))
    compile_report(clock)
    if as_json:
        click.echo(json.dumps(summary.to_dict()))
    else:
        ran = (f"{summary.ran} run now with {summary.workers} worker"
               f"{'s' if summary.workers != 1 else ''}" if summary.ran else "none to run")
        click.echo(f"{summary.runs} runs in {summary.chunks} chunks of up to {summary.chunk}: "
                   f"{summary.skipped} finished earlier, {ran}, {summary.wall_time_s:.1f} s")
        click.echo(f"{summary.finished} runs in {folder}/runs/ "
                   f"(persuasive.sweep.load({str(folder)!r}))")
    if summary.failures:
        for f in summary.failures[:10]:
            axes = ", ".join(f"{k} = {v!r}" for k, v in f["axes"].items())
            click.echo(f"error: run {f['run']} failed (seed {f['seed']}"
                       f"{', ' + axes if axes else ''}, config {f['config_hash']}): "
                       f"{f['error']}", err=True)
        if len(summary.failures) > 10:
            click.echo(f"error: ... and {len(summary.failures) - 10} more", err=True)
        click.echo(f"error: {len(summary.failures)} run(s) failed (listed in {folder}/failed/);"
                   " rerun the same command to retry them (only their chunks run again)",
                   err=True)
        click.get_current_context().exit(1)


def _parse_where(values: tuple[str, ...]) -> dict[str, Any]:
    """``("axis=value", ...)`` as a dict; values are read as TOML, else as text."""
    import tomllib

    from ..config import ConfigError

    out: dict[str, Any] = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--where {item!r} is not of the form AXIS=VALUE")
        try:
            out[key.strip()] = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key.strip()] = raw.strip()  # a bare word, e.g. mode=paper
    return out


@click.command("sweep")
@click.option("--from", "folder", required=True, type=click.Path(file_okay=False),
              help="Sweep folder written by 'persuasive sweep'.")
@click.option("--x", "x", required=True, metavar="AXIS", help="Axis along x (dotted field).")
@click.option("--y", "y", default=None, metavar="AXIS",
              help="Axis along y: a heatmap instead of a line plot.")
@click.option("--series", "series", default=None, metavar="AXIS",
              help="One line per value of this axis (e.g. av.kind) instead of a heatmap; "
                   "not with --y.")
@click.option("--metric", required=True, metavar="NAME",
              help="av_first_pct, hv_first_pct, same_step_pct, neither_pct, collision_pct, "
                   "infeasible_pct, both_cleared_pct, av_first_through_pct, deadlock_pct "
                   "(percent of runs, Wilson 95 % interval), min_distance_m, "
                   "min_distance_to_line_m, hv_role_changes, wait_s (means, normal 95 % "
                   "interval); a junction's (scenario.kind = junction): av_through_pct, "
                   "av_caused_collision_pct, human_collision_pct, deadlock_pct, "
                   "av_caused_deadlock_pct, av_inside_stood_pct, caused_delay_s, mean_wait_s, "
                   "throughput_veh_h.")
@click.option("--where", "where", multiple=True, metavar="AXIS=VALUE",
              help="Keep only runs with this value of another axis (repeatable); other "
                   "axes are pooled.")
@click.option("--out", required=True, type=click.Path(dir_okay=False),
              help="Figure file: .png, .svg or .pdf.")
def plot_sweep(folder, x, y, series, metric, where, out) -> None:
    """A metric of a sweep over one axis (line) or two (heatmap, or one line per value of
    --series), with 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    from ..plots.files import check_figure_path, save_figure
    from ..plots.sweep import sweep_figure
    from ..sweep.metrics import metric_grid

    from ..config import ConfigError

    if y is not None and series is not None:
        raise ConfigError("--series and --y are two ways to draw a second axis; allowed: "
                          "one of them")
    check_figure_path(out)  # before any work
    lock_output(out, "figure")
    data = metric_grid(folder, metric, x, y if series is None else series, _parse_where(where))
    click.echo(f"wrote {save_figure(sweep_figure(data, series is not None), out)}")


__all__ = ["plot_sweep", "sweep"]
