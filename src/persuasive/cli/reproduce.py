"""``persuasive reproduce``: the paper's Tables 1 and 2, beside the published numbers."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ._common import build_config, check_workers, compile_notice, config_options


@click.command()
@click.argument("table", type=click.Choice(["table1", "table2", "all"]))
@click.option("--seeds", type=click.IntRange(min=1), default=1000, show_default=True,
              help="Seeds 1..N per row (the published tables use 1000).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes [all cores; never more than the chunks of work].")
@config_options
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Results folder [results/<table>-<mode>-<settings hash>/]; with 'all', one "
                   "subfolder per table.")
@click.option("--force", is_flag=True,
              help="Replace a results folder made with other settings.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def reproduce(table, seeds, workers, mode, config_file, sets, out, force, as_json,
              quiet) -> None:
    """Rerun the paper's Table 1 and/or Table 2 beside the published numbers.

    Each row sets its own agents, p_a and p_a_hat on top of the base configuration
    (--config, --set, --mode).
    """
    from .. import experiments as ex
    from .._files import check_output_folder

    base = build_config(config_file, sets, {"mode": mode})
    tables = ex.TABLES if table == "all" else (table,)
    folders = {}
    for t in tables:
        if out:
            folder = Path(out) / t if table == "all" else Path(out)
        else:
            folder = ex.default_folder(base, t, seeds)
        check_output_folder(folder)
        ex.check_folder(folder, ex.settings_digest(base, t, seeds), force)  # before any work
        folders[t] = folder
    n_rows = sum(len(ex.PUBLISHED[t]) for t in tables)
    n_chunks = sum(len(ex.PUBLISHED[t]) for t in tables) * -(-seeds // 25)
    workers = check_workers(workers, n_chunks)
    compile_notice()
    progress = None if quiet else ex.tqdm_progress(n_rows)
    result = ex.reproduce(table, seeds, workers, None, base, progress=progress)
    for t in tables:
        ex.save(result, t, folders[t], force=True)
    if result.failures:
        for f in result.failures:
            click.echo(f"error: run failed: {f.describe()}", err=True)
    if as_json:
        payload = result.summaries[table] if table != "all" else dict(result.summaries)
        click.echo(json.dumps(payload))
    else:
        for t in tables:
            click.echo(ex.to_markdown(result.summaries[t]))
            click.echo(f"{ex.verdict(result.summaries[t], base)}")
            click.echo(f"written to {folders[t]}/\n")
        click.echo(f"{len(result.runs)} runs in {result.wall_time_s:.1f} s with "
                   f"{workers} worker{'s' if workers > 1 else ''}")
    if result.failures:
        click.echo(f"error: {len(result.failures)} run(s) failed and are left out of the "
                   "results (listed above and in summary.json)", err=True)
        click.get_current_context().exit(1)
