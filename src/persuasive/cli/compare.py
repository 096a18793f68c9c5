"""``persuasive compare``: every AV planner against every human model on the same runs."""

from __future__ import annotations

import json

import click

from ..config import AV_KINDS, ROLES, SHIELD_KINDS, SIMULATED_HV_KINDS, Config
from ..studies.compare import DEFAULT_HV_KINDS
from ._common import (INTERACTIONS_HELP, KIND_OPTIONS, SEED_MAX, Count, build_config,
                      check_workers, compile_notice, config_options, junction_compile_notice,
                      junction_config, junction_options, kinds_text, lock_output, mode_given,
                      progress_bar, scenario_option, workers_type)

#: The human kinds left out by default (they need more than a configuration, e.g. replay's
#: recording), named in the help.
_NOT_DEFAULT = tuple(k for k in SIMULATED_HV_KINDS if k not in DEFAULT_HV_KINDS)


def check_hv_role(hv_role: str | None, base: Config, avs, hvs) -> None:
    """Refuse an explicit ``--hv-role`` that no compared kind reads (exit status 2): it is
    used as soon as one human kind holds a role or one AV is the lfg player (those pairs start
    from it; the others ignore it, as a configuration file's ``hv.role`` would be)."""
    if hv_role is None:
        return
    option = KIND_OPTIONS["hv_role"]
    if any(option.used_by(base.with_overrides({"av.kind": av, "hv.kind": hv}))
           for av in avs for hv in hvs):
        return
    raise click.UsageError(f"--hv-role = {hv_role} is not used by the {kinds_text(hvs)} "
                           f"HV{'s' * (len(hvs) > 1)} with the {kinds_text(avs)} "
                           f"AV{'s' * (len(avs) > 1)}; it is {option.users()}")


@click.command()
@click.option("--av", "av_kinds", default=None, metavar="KINDS",
              help=f"AV planners, comma-separated [all: {kinds_text(AV_KINDS, sep=',')}].")
@click.option("--hv", "hv_kinds", default=None, metavar="KINDS",
              help="Human models, comma-separated [all"
                   + (f" but {kinds_text(_NOT_DEFAULT, sep=',')}" if _NOT_DEFAULT else "")
                   + f": {kinds_text(DEFAULT_HV_KINDS, sep=',')}].")
@click.option("--shield", "shields", default=None, metavar="SETTINGS",
              help=f"Safety shields to compare on the same seeds, comma-separated, of "
                   f"{kinds_text(SHIELD_KINDS)} (docs/method.md §12) [the "
                   f"configuration's: {Config(mode='paper').shield} in paper mode, "
                   f"{Config(mode='corrected').shield} in corrected mode].")
@click.option("--hv-role", type=click.Choice(list(ROLES)), default=None,
              help=f"Initial role of the humans that hold one [{Config().hv.role}]; "
                   f"{KIND_OPTIONS['hv_role'].users()}.")
@scenario_option(f"Geometry [{Config().scenario.kind}]", many=True)
@junction_options
@click.option("--seeds", type=Count(1, SEED_MAX), default=200, show_default=True,
              help="Seeds 1..N for every pair (at most 1,000,000 runs in all: seeds x pairs "
                   "x interactions).")
@click.option("--workers", type=workers_type(), default=None,
              help="Worker processes [all cores].")
@config_options
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Comparison folder [results/compare-<grid hash>/]; rerunning resumes.")
@click.option("--force", is_flag=True,
              help="Replace this command's own earlier results in the folder (another "
                   "comparison's manifest.json, runs/part-*.parquet, failed/failed-*.json, "
                   "summary.json, summary.md); other files are kept.")
@click.option("--timing-seeds", type=Count(1, 1000), default=3, show_default=True,
              help="Seeds per pair whose AV decisions are timed (in this process; never more "
                   "than --seeds).")
@click.option("--interactions", type=Count(1, 1000), default=None, help=INTERACTIONS_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print the rows as one JSON list.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def compare(av_kinds, hv_kinds, shields, hv_role, scenario, vehicles, variant, seeds, workers,
            mode, config_file, sets, out, force, timing_seeds, interactions, as_json,
            quiet) -> None:
    """Compare AV planners and human models on the same seeds (docs/method.md §11).

    Each pair runs on seeds 1..N with independent random streams per agent, so a seed gives
    the same initial state and the same human draws whatever the AV. With --scenario
    junction: the AV among --vehicles vehicles (persuasive.studies.junction_compare; --hv
    gives each cell's humans, one kind each, default the configuration's
    junction.hv_kinds). Prints one row per pair
    with 95 % bootstrap intervals, then each AV's paired differences against persuasive.

    A comparison holds at most 1,000,000 runs, each repeated interaction counted (seeds x AV
    kinds x human kinds x shield settings x interactions), and the progress bar counts those
    runs. --hv-role is refused when no compared human holds a role and no AV is the lfg
    player.
    """
    from .._files import check_output_folder
    from ..studies import compare as cmp

    options = {"mode": mode, "sets": sets, "config_file": config_file,
               "vehicles": vehicles, "variant": variant}
    base = build_config(config_file, sets, {"mode": mode, "hv.role": hv_role,
                                           "scenario.kind": scenario})
    if base.scenario.kind == "junction":
        _junction(base, options, av_kinds, hv_kinds, shields, hv_role, seeds, workers, out,
                  force, interactions, as_json, quiet)
        return
    base = junction_config(base, options)  # --vehicles, --variant: refused here
    if interactions is not None:
        base = base.with_overrides({"simulation.interactions": interactions})
    avs = cmp.parse_kinds(av_kinds, AV_KINDS, "--av", AV_KINDS)
    hvs = cmp.parse_kinds(hv_kinds, SIMULATED_HV_KINDS, "--hv", cmp.DEFAULT_HV_KINDS)
    shield_list = cmp.parse_kinds(shields, SHIELD_KINDS, "--shield", SHIELD_KINDS) \
        if shields is not None else None
    check_hv_role(hv_role, base, avs, hvs)
    cmp.check_size(seeds, len(avs) * len(hvs) * len(shield_list or (None,)),
                   cmp.n_interactions(base), "--seeds")
    if out is not None:
        check_output_folder(out, "comparison folder")  # before any work
    if base.simulation.streams == "legacy" and "lfg" in avs:
        click.echo("warning: simulation.streams = legacy: the human's draws depend on whether "
                   "the AV draws (the lfg AV does), so those runs are not paired", err=True)
    grid = cmp.comparison_grid(cmp.comparison_base(base), avs, hvs, seeds,
                               shield_list)  # checks it all
    lock_output(out if out is not None else cmp.default_folder(grid), "comparison folder")
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


def _junction(base: Config, options: dict, av_kinds, hv_kinds, shields, hv_role, seeds,
              workers, out, force, interactions, as_json, quiet) -> None:
    """``compare --scenario junction`` (persuasive.studies.junction_compare): in corrected
    mode unless a mode is given; --hv-role and --interactions are two-vehicle options."""
    from .._files import check_replaceable_folder, json_safe
    from ..studies import compare as cmp
    from ..studies import junction_compare as jc

    for flag, given in (("--hv-role", hv_role), ("--interactions", interactions)):
        if given is not None:
            raise click.UsageError(f"{flag} is a two-vehicle option; it does not go with "
                                   "--scenario junction")
    if not mode_given(options):
        base = base.with_overrides({"mode": "corrected"})
    base = junction_config(base, options)
    avs = cmp.parse_kinds(av_kinds, AV_KINDS, "--av", AV_KINDS)
    hv_allowed = tuple(k for k in SIMULATED_HV_KINDS if k != "replay")
    hvs = cmp.parse_kinds(hv_kinds, hv_allowed, "--hv", hv_allowed) \
        if hv_kinds is not None else None
    shield_list = cmp.parse_kinds(shields, SHIELD_KINDS, "--shield", SHIELD_KINDS) \
        if shields is not None else None
    n_cells = len(jc.cells_of(base, avs, hvs, shield_list))  # every cell checked here
    cmp.check_size(seeds, n_cells, 2, "--seeds")  # each seed twice: with and without the AV
    folder = out if out is not None else jc.default_folder(base, avs, hvs, shield_list, seeds)
    check_replaceable_folder(folder, force, "comparison folder", owned=jc.OUT_FILES)
    lock_output(folder, "comparison folder")
    workers = check_workers(workers, n_cells * seeds)
    junction_compile_notice()
    progress = progress_bar(quiet)
    try:
        summary = jc.run_comparison(base, avs, hvs, shield_list, seeds, folder, workers,
                                    progress)
    finally:
        if progress is not None:
            progress.close()  # type: ignore[attr-defined]
    if as_json:
        click.echo(json.dumps(json_safe(summary), allow_nan=False))
        return
    spec = base.junction_spec
    click.echo(f"junction ({summary['variant']}, {spec.n_vehicles} vehicles, {spec.lanes} "
               f"lane(s), humans playing {spec.opponents}), {base.mode} mode, seeds 1..{seeds}, "
               f"{spec.duration_s:g}-s runs")
    click.echo(jc.to_markdown(summary))
    click.echo(f"written to {folder}/")

