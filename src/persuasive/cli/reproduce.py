"""``persuasive reproduce``: the paper's Tables 1 and 2, beside the published numbers."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .._compile import StudyClock
from ._common import (SEED_MAX, Count, build_config, check_workers, compile_notice,
                      compile_report, config_options, lock_output, progress_bar,
                      scenario_option, shield_option, workers_type)


@click.command()
@click.argument("table", type=click.Choice(["table1", "table2", "all"]))
@click.option("--seeds", type=Count(1, SEED_MAX), default=1000, show_default=True,
              help="Seeds 1..N per row (the published tables use 1000).")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes [all cores; never more than the chunks of work].")
@scenario_option("Run the tables in another scenario [intersection, the paper's]")
@shield_option
@config_options
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Results folder [results/<table>-<mode>-<settings hash>/]; with 'all', one "
                   "subfolder per table.")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier results in the folder (a reproduction "
                   "made with other settings: manifest.json, runs/part-*.parquet, "
                   "failed/failed-*.json, summary.json, summary.md, config.toml); other files "
                   "are kept.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def reproduce(table, seeds, workers, scenario, shield, mode, config_file, sets, out, force,
              as_json, quiet) -> None:
    """Rerun the paper's Table 1 and/or Table 2 beside the published numbers.

    Each row sets its own agents, p_a and p_a_hat on top of the base configuration
    (--config, --set, --mode). The runs go through the sweep runner (Dask): a reproduction
    stopped midway resumes when the same command runs again into the same folder.
    """
    from .. import experiments as ex
    from .._files import check_output_folder

    tables = ex.TABLES if table == "all" else (table,)
    ex.check_seeds(seeds, sum(len(ex.PUBLISHED[t]) for t in tables), "--seeds")
    base = build_config(config_file, sets, {"mode": mode, "scenario.kind": scenario,
                                           "av.shield": shield})
    grids = {t: ex.table_grid(t, base, seeds) for t in tables}
    folders = {}
    for t in tables:
        if out:
            folder = Path(out) / t if table == "all" else Path(out)
        else:
            folder = ex.default_folder(base, t, seeds)
        check_output_folder(folder)
        ex.check_folder(folder, grids[t], force)  # before any work
        folders[t] = folder
    for folder in folders.values():
        lock_output(folder, "results folder")
    n_rows = sum(len(ex.PUBLISHED[t]) for t in tables)
    total = sum(len(g) for g in grids.values())
    from ..sweep.store import default_chunk

    workers = check_workers(workers, max(-(-len(g) // default_chunk(len(g)))
                                         for g in grids.values()))
    compile_notice()
    progress = progress_bar(quiet, n_rows)
    clock = StudyClock()
    try:  # every table in one call: one cluster of workers for the whole command
        result = ex.reproduce(table, seeds, workers, None, base, progress=progress,
                              out=folders, force=force)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    summaries = result.summaries
    failures = list(result.failures)
    for t in tables:
        ex.save(result, t, folders[t])
    for f in failures:
        click.echo(f"error: run failed: {f.describe()}", err=True)
    compile_report(clock)
    if as_json:
        payload = summaries[table] if table != "all" else dict(summaries)
        click.echo(json.dumps(payload))
    else:
        for t in tables:
            click.echo(ex.to_markdown(summaries[t]))
            click.echo(f"{ex.verdict(summaries[t], base)}")
            click.echo(f"written to {folders[t]}/\n")
        # the study's own time: a first run's compile is said apart (compile_report)
        wall = max(0.0, result.wall_time_s - clock.compile_s)
        skipped, ran = result.skipped, result.ran
        with_workers = f"with {workers} worker{'s' if workers > 1 else ''}"
        if not skipped:
            click.echo(f"{total - len(failures)} runs in {wall:.1f} s {with_workers}")
        else:  # resumed: as 'persuasive sweep' says it
            now = f"{ran} run now {with_workers}" if ran else "none to run"
            click.echo(f"{total} runs: {skipped} finished earlier, {now}, {wall:.1f} s")
    if failures:
        click.echo(f"error: {len(failures)} run(s) failed and are left out of the results "
                   "(listed above and in summary.json); run the same command again to retry "
                   "them", err=True)
        click.get_current_context().exit(1)
