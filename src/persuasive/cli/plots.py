"""The ``persuasive plot`` and ``persuasive animate`` commands (registered by ``persuasive.cli``).

The run options are those of ``persuasive simulate`` (:func:`persuasive.cli._common.run_options`),
except that ``--seed`` defaults to the run the authors show in their Figs. 2 and 3 (996), so that
``persuasive plot profile`` draws the paper's figure; ``simulate`` defaults to seed 1. matplotlib
and the simulation are imported inside the commands, so ``persuasive --help`` stays fast and the
command line never pulls matplotlib in unless a figure is drawn; the Agg backend is forced there,
as no window is ever opened. Every file is checked for a known extension before any work, and
written to a temporary sibling first, then renamed; a second command writing the same file
meanwhile is refused (:func:`persuasive.cli._common.lock_output`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import click
from click.core import ParameterSource

from ._common import (PAPER_SEED, Count, check_input_files, check_kind_options,
                      check_readable, compile_notice, config_of, junction_compile_notice,
                      kind_configs, lock_output,
                      run_options)

_SEED_HELP = f"Run seed [{PAPER_SEED}: the run shown in the paper's Figs. 2 and 3]."


def _plots():
    """The plotting module, with the non-interactive backend forced first."""
    import matplotlib

    matplotlib.use("Agg")
    from .. import plots

    return plots


#: The options that describe the run to simulate, which ``--from`` replaces.
_RUN_PARAMS = ("av", "hv", "hv_role", "pa", "pa_hat", "scenario", "seed", "mode",
               "config_file", "sets", "single", "vehicles", "variant")


def _check_from(source: str | None) -> None:
    """Refuse the options that ``--from`` overrides (a saved run has its own seed,
    configuration and kinds): a usage error, exit status 2, naming them."""
    if source is None:
        return
    ctx = click.get_current_context()
    given = [p.opts[0] for p in ctx.command.params if p.name in _RUN_PARAMS
             and ctx.get_parameter_source(p.name) not in (None, ParameterSource.DEFAULT,
                                                            ParameterSource.DEFAULT_MAP)]
    if given:
        raise click.UsageError(f"{', '.join(given)} cannot be used with --from: the saved "
                               "run has its own seed and configuration")


def _runs(single: bool, run: dict) -> Callable[[], tuple]:
    """Check the runs to plot, then return what makes them: the run the options describe
    (``single``), the run saved in ``--from``, or the LFG-AV and persuasive-AV runs of Figs.
    2-3. Everything is checked here, before matplotlib is imported or a kernel compiled:
    ``--from`` a file that cannot be read, options it overrides, and ``--pa``, ``--pa-hat`` or
    ``--hv-role`` that none of the runs reads
    (:func:`persuasive.cli._common.check_kind_options`) are refused."""
    from ..simulation import load_record, simulate

    source = run.pop("source", None)
    fit_run = run.pop("fit_run", None)
    _check_from(source)
    if fit_run is not None and source is None:
        raise click.UsageError("--run applies only with --from a fit's file (persuasive fit "
                               "--out FILE.parquet)")
    if source is not None:
        from ..fitting.output import is_fit_file, load_fitted_run

        check_readable([source], "run file")
        if is_fit_file(source):  # a fit's runs, with the human's smoothed role
            return lambda: (load_fitted_run(source, 0 if fit_run is None else fit_run),)
        if fit_run is not None:
            raise click.UsageError("--run applies only to a fit's file (persuasive fit --out "
                                   "FILE.parquet)")
        return lambda: (load_record(source),)
    if single:
        configs = [config_of(run)]
    elif run.get("av") is not None:
        raise click.UsageError("--av applies only with --single (without it both the LFG AV "
                               "and the persuasive AV are plotted)")
    else:
        configs = [config_of({**run, "av": kind}) for kind in ("lfg", "persuasive")]
    # an option is refused only when neither run reads it (--pa-hat: the persuasive AV's)
    check_kind_options(run, configs)
    check_input_files(*configs)

    def make() -> tuple:
        compile_notice()
        return tuple(simulate(config, run["seed"]) for config in configs)

    return make


def _junction_run(run: dict) -> Callable[[], object] | None:
    """What makes the junction run the options describe (``--scenario junction``, or a
    configuration's ``scenario.kind = "junction"``): a finished
    ``persuasive.many.world.JunctionWorld``; None for a two-vehicle run (and with
    ``--from``). Checked here, before any work; ``--single`` changes nothing (one run)."""
    if run.get("source") is not None:
        return None
    config = config_of(dict(run))
    if config.scenario.kind != "junction":
        return None
    check_kind_options(run, kind_configs(config))

    def make():
        from ..many.world import JunctionWorld

        junction_compile_notice()
        return JunctionWorld.of(config, run["seed"]).run()

    return make


def _out_option(help_text: str) -> Callable:
    return click.option("--out", required=True, type=click.Path(dir_okay=False),
                        help=help_text)


@click.group()
def plot() -> None:
    """Draw the paper's figures (profiles, top view) and reproduced tables."""


def _single_option(func: Callable) -> Callable:
    return click.option("--single", is_flag=True,
                        help="Plot the one run the options describe instead of both cases "
                             "(LFG AV and MPC AV).")(func)


def _from_option(func: Callable) -> Callable:
    return click.option("--from", "source", type=click.Path(dir_okay=False), default=None,
                        help="Plot a saved run instead of simulating one: a Parquet log of "
                             "'simulate --out', a recorded trial of 'drive', or a fit's runs "
                             "('fit --out FILE.parquet', with --run); it has its own seed and "
                             "configuration: no run option goes with it.")(func)


def _fit_run_option(func: Callable) -> Callable:
    return click.option("--run", "fit_run", type=Count(0), default=None,
                        metavar="K", help="With --from a fit's file: the run to plot [0]; "
                                          "its smoothed role is drawn on the role row.")(func)


@plot.command()
@run_options(seed_default=PAPER_SEED, seed_help=_SEED_HELP)
@_single_option
@_from_option
@_fit_run_option
@_out_option("Figure file: .png, .svg or .pdf.")
def profile(single, out, **run) -> None:
    """Roles, beliefs, speeds and accelerations over time (the paper's Fig. 2); at a
    junction (--scenario junction) every vehicle's speed and acceleration."""
    junction = _junction_run(run)
    if junction is not None:
        from ..plots import junction as draw

        plots = _plots()
        plots.check_figure_path(out)
        lock_output(out, "figure")
        click.echo(f"wrote {plots.save_figure(draw.profile_figure(junction()), out)}")
        return
    make = _runs(single, run)
    plots = _plots()
    plots.check_figure_path(out)
    lock_output(out, "figure")
    runs = make()
    fig = plots.profile_single(*runs) if len(runs) == 1 else plots.profile_figure(*runs)
    click.echo(f"wrote {plots.save_figure(fig, out)}")


@plot.command()
@run_options(seed_default=PAPER_SEED, seed_help=_SEED_HELP)
@_single_option
@click.option("--every", "every_s", type=click.FloatRange(min=0.0, min_open=True), default=1.0,
              show_default=True, metavar="SECONDS", help="Time between vehicle snapshots.")
@_from_option
@_out_option("Figure file: .png, .svg or .pdf.")
def topview(single, every_s, out, **run) -> None:
    """The intersection from above with vehicle snapshots (the paper's Fig. 3); at a
    junction (--scenario junction) every vehicle's path, with footprints at four times or
    every --every seconds."""
    junction = _junction_run(run)
    if junction is not None:
        from ..plots import junction as draw

        plots = _plots()
        plots.check_figure_path(out)
        lock_output(out, "figure")
        given = click.get_current_context().get_parameter_source("every_s")
        every = every_s if given == ParameterSource.COMMANDLINE else None
        fig = draw.topview_figure(junction(), every_s=every)
        click.echo(f"wrote {plots.save_figure(fig, out)}")
        return
    make = _runs(single, run)
    plots = _plots()
    plots.check_figure_path(out)
    lock_output(out, "figure")
    runs = make()
    fig = (plots.topview_single(*runs, every_s=every_s) if len(runs) == 1
           else plots.topview_figure(*runs, every_s=every_s))
    click.echo(f"wrote {plots.save_figure(fig, out)}")


@plot.command()
@click.option("--from", "results", required=True, type=click.Path(file_okay=False),
              help="Results folder of 'persuasive reproduce' (holds summary.json).")
@_out_option("Figure file: .png, .svg or .pdf.")
def table(results: str, out: str) -> None:
    """A reproduced table as bars beside the published shares."""
    from ..experiments import load_summary

    plots = _plots()
    plots.check_figure_path(out)
    lock_output(out, "figure")
    fig = plots.table_figure(load_summary(Path(results)))
    click.echo(f"wrote {plots.save_figure(fig, out)}")


@click.command("compare")
@click.option("--from", "results", required=True, type=click.Path(file_okay=False),
              help="Folder of 'persuasive compare' (holds summary.json).")
@_out_option("Figure file: .png, .svg or .pdf.")
def plot_compare(results: str, out: str) -> None:
    """A comparison: AV-first shares and collisions per pair, and the delays' spread."""
    from .. import sweep
    from ..studies.compare import load_summary

    plots = _plots()
    plots.check_figure_path(out)
    lock_output(out, "figure")
    summary = load_summary(Path(results))
    runs = sweep.load(Path(results))
    fig = plots.compare_figure(summary, runs)
    click.echo(f"wrote {plots.save_figure(fig, out)}")


@click.command()
@run_options(seed_default=PAPER_SEED, seed_help=_SEED_HELP)
@click.option("--fps", type=Count(1, 120), default=10, show_default=True,
              help="Frames per second (10 is real time).")
@_from_option
@_out_option("Animation file: .mp4 or .gif.")
def animate(fps, out, **run) -> None:
    """Animate one run: the top view, with the beliefs and roles shown live (at a junction,
    --scenario junction: every vehicle's footprint)."""
    junction = _junction_run(run)
    if junction is not None:
        from ..plots import junction as draw

        plots = _plots()
        plots.check_animation_path(out)
        lock_output(out, "animation")
        world = junction()
        path = draw.video(world, out, fps=fps)
        click.echo(f"wrote {path} ({world.k + 1} frames at {fps} fps)")
        return
    make = _runs(True, run)
    plots = _plots()
    plots.check_animation_path(out)
    lock_output(out, "animation")
    (record,) = make()
    path = plots.animate(record, out, fps=fps)
    click.echo(f"wrote {path} ({len(record.log['step'])} frames at {fps} fps)")


__all__ = ["animate", "plot", "plot_compare"]
