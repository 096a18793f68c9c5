"""``persuasive compare``: every AV planner against every human model on the same runs."""

from __future__ import annotations

import json

import click

from ._common import (INTERACTIONS_HELP, build_config, check_workers, compile_notice,
                      config_options, progress_bar)


@click.command()
@click.option("--av", "av_kinds", default=None, metavar="KINDS",
              help="AV planners, comma-separated [all: persuasive,passive,cv,lfg,yield].")
@click.option("--hv", "hv_kinds", default=None, metavar="KINDS",
              help="Human models, comma-separated [all but replay: "
                   "lfg,stubborn,noisy,idm,aggressive,adversary,deceptive,random].")
@click.option("--shield", "shields", default=None, metavar="SETTINGS",
              help="Safety shields to compare on the same seeds, comma-separated, e.g. "
                   "off,worst-case (docs/method.md §12) [the configuration's: off in paper "
                   "mode, worst-case in corrected mode].")
@click.option("--hv-role", type=click.Choice(["leader", "follower"]), default=None,
              help="Initial role of the LFG-type humans [leader].")
@click.option("--scenario", type=click.Choice(["intersection", "crossing", "left-turn",
                                               "merge"]), default=None,
              help="Geometry [intersection].")
@click.option("--seeds", type=click.IntRange(min=1), default=200, show_default=True,
              help="Seeds 1..N for every pair.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes [all cores].")
@config_options
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Comparison folder [results/compare-<grid hash>/]; rerunning resumes.")
@click.option("--force", is_flag=True, help="Replace a folder holding another comparison.")
@click.option("--timing-seeds", type=click.IntRange(min=1), default=3, show_default=True,
              help="Seeds per pair whose AV decisions are timed (in this process).")
@click.option("--interactions", type=click.IntRange(1, 1000), default=None,
              help=INTERACTIONS_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print the rows as one JSON list.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def compare(av_kinds, hv_kinds, shields, hv_role, scenario, seeds, workers, mode, config_file,
            sets, out, force, timing_seeds, interactions, as_json, quiet) -> None:
    """Compare AV planners and human models on the same seeds (docs/method.md §11).

    Each pair runs on seeds 1..N with independent random streams per agent, so a seed gives
    the same initial state and the same human draws whatever the AV. Prints one row per pair
    with 95 % bootstrap intervals, then each AV's paired differences against persuasive.
    """
    from ..config import AV_KINDS, SHIELD_KINDS, SIMULATED_HV_KINDS
    from ..experiments import check_seeds
    from ..studies import compare as cmp

    base = build_config(config_file, sets, {"mode": mode, "hv.role": hv_role,
                                           "scenario.kind": scenario,
                                           "simulation.interactions": interactions})
    avs = cmp.parse_kinds(av_kinds, AV_KINDS, "--av", AV_KINDS)
    hvs = cmp.parse_kinds(hv_kinds, SIMULATED_HV_KINDS, "--hv", cmp.DEFAULT_HV_KINDS)
    shield_list = cmp.parse_kinds(shields, SHIELD_KINDS, "--shield", SHIELD_KINDS) \
        if shields is not None else None
    check_seeds(seeds, len(avs) * len(hvs) * len(shield_list or (None,)), "--seeds", "pairs")
    if base.simulation.streams == "legacy" and "lfg" in avs:
        click.echo("warning: simulation.streams = legacy: the human's draws depend on whether "
                   "the AV draws (the lfg AV does), so those runs are not paired", err=True)
    grid = cmp.comparison_grid(cmp.comparison_base(base), avs, hvs, seeds,
                               shield_list)  # checks it all
    workers = check_workers(workers, max(1, len(grid) // 25))
    compile_notice()
    progress = progress_bar(quiet)
    try:
        result = cmp.run_comparison(base, avs, hvs, seeds, out, workers, force, timing_seeds,
                                    progress, shield_list)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    if as_json:
        click.echo(json.dumps(cmp.json_rows(result.summary)))
    else:
        click.echo(cmp.to_markdown(result.summary))
        click.echo(f"written to {result.folder}/")
    if result.failures:
        click.echo(f"error: {result.failures} run(s) failed (listed in {result.folder}/failed/);"
                   " run the same command again to retry them", err=True)
        click.get_current_context().exit(1)
