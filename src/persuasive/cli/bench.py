"""``persuasive bench``: timings of the game solve, the MPC decision and the reproduction."""

from __future__ import annotations

import json

import click

from ._common import compile_notice


@click.command()
@click.option("--runs", "n_runs", type=click.IntRange(min=1), default=10, show_default=True,
              help="Closed-loop runs whose states are replayed.")
@click.option("--repeats", type=click.IntRange(min=1), default=3, show_default=True,
              help="Passes over those states.")
@click.option("--full", is_flag=True, help="Also time 'reproduce all' (16,000 runs).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Workers for --full [all cores].")
@click.option("--reference", is_flag=True, help="Also time the plain NumPy reference path.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def bench(n_runs, repeats, full, workers, reference, as_json) -> None:
    """Time a game solve, an MPC decision, a run and (--full) the whole reproduction."""
    from ..bench import bench as run_bench

    compile_notice()
    result = run_bench(n_runs, repeats, full, reference, workers)
    if as_json:
        click.echo(json.dumps(result))
        return
    m = result["machine"]
    click.echo(f"machine: {m['cpus']} cpus, {m['processor']}, Python {m['python']}")
    click.echo(f"game solve (libraries included): median {result['game_solve_us_median']:.1f} us,"
               f" p99 {result['game_solve_us_p99']:.1f} us")
    click.echo(f"MPC decision: median {result['mpc_decision_ms_median']:.3f} ms, "
               f"p99 {result['mpc_decision_ms_p99']:.3f} ms")
    click.echo(f"closed-loop MPC run (61 steps): median {result['mpc_run_ms_median']:.2f} ms")
    if reference:
        click.echo("reference NumPy path: game solve "
                   f"{result['reference_game_solve_us_median']:.0f} us, MPC decision "
                   f"{result['reference_mpc_decision_ms_median']:.1f} ms")
    if full:
        click.echo(f"reproduce all (16,000 runs, {result['reproduce_workers']} workers): "
                   f"{result['reproduce_all_s']:.1f} s, peak memory at most "
                   f"{result['reproduce_peak_rss_mb']:.0f} MB")
