"""The ``persuasive`` command line.

Every command builds one validated :class:`~persuasive.config.Config`: the paper's defaults,
then ``--config FILE.toml``, then ``--set section.field=value`` overrides, then the explicit
options (``--av``, ``--hv-role``, ``--pa``, ``--pa-hat``, ``--mode``). Bad input ends the
command with one line on stderr (``error: ...``) and exit status 2; nothing already written
is touched, and results are written to a temporary file first, then renamed.
"""

from __future__ import annotations

import json
import os
import sys
import time
import tomllib
from pathlib import Path
from typing import Any, Callable

import click

from . import __version__
from ._files import atomic_write
from .config import MODES, ROLES, Config, ConfigError


def _parse_set(values: tuple[str, ...]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r} is not of the form section.field=value")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()  # a bare word, e.g. --set simulation.av=lfg
        out[key.strip()] = value
    return out


def build_config(config_file: str | None, sets: tuple[str, ...], mode: str | None = None,
                 av: str | None = None, hv_role: str | None = None, pa: float | None = None,
                 pa_hat: float | None = None) -> Config:
    """The configuration of a command (see the module docstring for the precedence)."""
    config = Config.from_toml(config_file) if config_file else Config()
    overrides = _parse_set(sets)
    for key, value in (("mode", mode), ("simulation.av", av), ("simulation.hv_role", hv_role),
                       ("roles.p_a", pa), ("mpc.p_a_hat", pa_hat)):
        if value is not None:
            overrides[key] = value
    return config.with_overrides(overrides) if overrides else config


def run_options(seed_default: int = 1) -> Callable[[Callable], Callable]:
    """The options that define one closed-loop run (shared by simulate, plot and animate)."""
    options = [
        click.option("--av", type=click.Choice(["mpc", "lfg"]), default=None,
                     help="AV planner: persuasive branch MPC or LFG (2-LFG case) [mpc]."),
        click.option("--hv-role", type=click.Choice(list(ROLES)), default=None,
                     help="HV initial role [leader]."),
        click.option("--pa", type=float, default=None, help="Human's p_a in [0, 1] [1.0]."),
        click.option("--pa-hat", type=float, default=None,
                     help="AV's estimate of p_a in [0, 1] [equal to --pa]."),
        click.option("--seed", type=int, default=seed_default, show_default=True,
                     help="Run seed."),
        click.option("--mode", type=click.Choice(list(MODES)), default=None,
                     help="paper (quirks Q1..Q7) or corrected [paper]."),
        click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
                     help="TOML file of parameters."),
        click.option("--set", "sets", multiple=True, metavar="SECTION.FIELD=VALUE",
                     help="Override one parameter (repeatable), e.g. mpc.epsilon=0.05."),
    ]

    def decorate(func: Callable) -> Callable:
        for option in reversed(options):
            func = option(func)
        return func

    return decorate


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="persuasive")
def cli() -> None:
    """Persuasive trajectory planning with an adaptive leader-follower game."""


@cli.command()
@run_options()
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the per-step log here (Parquet).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def simulate(av, hv_role, pa, pa_hat, seed, mode, config_file, sets, out, as_json) -> None:
    """Simulate one closed-loop run of the intersection."""
    from .simulation import ARRIVAL_LABELS, simulate as run

    config = build_config(config_file, sets, mode, av, hv_role, pa, pa_hat)
    t0 = time.perf_counter()
    record = run(config, seed)
    elapsed = time.perf_counter() - t0
    if out:
        frame = record.frame()
        atomic_write(out, lambda p: frame.to_parquet(p, index=False))
    summary = record.summary()
    if as_json:
        click.echo(json.dumps(summary))
        return
    o = record.outcome
    dt = config.simulation.dt_s
    line = ARRIVAL_LABELS[o.first_at_line]
    where = ""
    if o.first_at_line:
        where = f" (after step {o.idx_end}, t = {(o.idx_end + 1) * dt:.1f} s)"
    pa_hat_text = f", p_a_hat = {config.p_a_hat:g}" if config.simulation.av == "mpc" else ""
    click.echo(
        f"{config.simulation.av.upper()} AV, HV starts as {config.simulation.hv_role}, "
        f"p_a = {config.roles.p_a:g}{pa_hat_text}, seed {record.seed}, {config.mode} mode"
    )
    s0, v0 = record.hv_initial_state
    click.echo(f"HV initial state: s = {s0:.3f} m, v = {v0:.3f} m/s")
    click.echo(f"first at the crossing line: {line}{where}; "
               f"first at the conflict point: {ARRIVAL_LABELS[o.first_at_conflict_point]}")
    click.echo(f"collision: {'yes' if o.collision else 'no'}; minimum distance "
               f"{o.min_distance_to_line_m:.2f} m up to the line, {o.min_distance_m:.2f} m over "
               f"the run (safe set {config.vehicle.min_dist_m:g} m)")
    changes = f"HV role changes: {o.hv_role_changes}"
    if config.simulation.av == "lfg":
        changes += f"; AV role changes: {o.av_role_changes}"
    else:
        changes += f"; infeasible MPC steps: {o.infeasible_steps}"
    click.echo(changes)
    click.echo(f"time: {elapsed:.3f} s" + (f"; per-step log written to {out}" if out else ""))


@cli.command()
@click.argument("table", type=click.Choice(["table1", "table2", "all"]))
@click.option("--seeds", type=click.IntRange(min=1), default=1000, show_default=True,
              help="Seeds 1..N per row.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes [all cores].")
@click.option("--mode", type=click.Choice(list(MODES)), default="paper", show_default=True)
@click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
              help="TOML file of base parameters (each row sets its agents and p_a, p_a_hat).")
@click.option("--set", "sets", multiple=True, metavar="SECTION.FIELD=VALUE",
              help="Override one base parameter (repeatable).")
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Results folder [results/<table>-<mode>/]; with 'all', one subfolder per "
                   "table.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def reproduce(table, seeds, workers, mode, config_file, sets, out, as_json, quiet) -> None:
    """Rerun the paper's Table 1 and/or Table 2 beside the published numbers."""
    from . import experiments as ex

    base = build_config(config_file, sets)
    tables = ex.TABLES if table == "all" else (table,)
    n_rows = sum(len(ex.PUBLISHED[t]) for t in tables)
    progress = None if quiet else ex.tqdm_progress(n_rows)
    result = ex.reproduce(table, seeds, workers, mode, base, progress=progress)
    for t in tables:
        folder = Path(out) / t if out and table == "all" else Path(out or f"results/{t}-{mode}")
        ex.save(result, t, folder)
    if as_json:
        payload = result.summaries[table] if table != "all" else dict(result.summaries)
        click.echo(json.dumps(payload))
        return
    for t in tables:
        click.echo(ex.to_markdown(result.summaries[t]))
        verdict = "every cell equals" if ex.matches_published(result.summaries[t]) else \
            "NOT every cell equals"
        click.echo(f"{verdict} the published one (mode {mode}).\n")
    click.echo(f"{len(result.runs)} runs in {result.wall_time_s:.1f} s with "
               f"{workers or os.cpu_count()} workers")


@cli.command()
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
    from .bench import bench as run_bench

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


from ._cli_plots import animate, plot  # noqa: E402
cli.add_command(plot); cli.add_command(animate)


def main(argv: list[str] | None = None) -> int:
    """Entry point: one-line errors, exit status 2 for bad input."""
    try:
        rv = cli.main(args=argv, prog_name="persuasive", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("error: aborted", err=True)
        return 130
    except click.ClickException as exc:
        click.echo(f"error: {exc.format_message()}", err=True)
        return exc.exit_code
    except ConfigError as exc:
        click.echo(f"error: {exc}", err=True)
        return 2
    except OSError as exc:
        click.echo(f"error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), err=True)
        return 1
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
