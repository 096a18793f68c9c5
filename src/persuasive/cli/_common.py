"""What every command shares: building the configuration, the run options, output checks.

Precedence, the same for every command: an explicit option (``--mode``, ``--av``, ``--pa``,
...) beats ``--set section.field=value``, which beats ``--config FILE.toml``, which beats the
defaults (the paper's values).
"""

from __future__ import annotations

import os
import sys
import tomllib
from typing import Any, Callable

import click

from ..config import (AV_KIND_ALIASES, AV_KINDS, MODES, ROLES, SCENARIO_KINDS,
                      SHIELD_KINDS, SIMULATED_HV_KINDS, Config, ConfigError)

#: Seed of the run the paper shows in its Figs. 2 and 3 (the default of the figure commands).
PAPER_SEED = 996


def parse_set(values: tuple[str, ...]) -> dict[str, Any]:
    """``("section.field=value", ...)`` as a dict; values are read as TOML, else as text."""
    out: dict[str, Any] = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r} is not of the form section.field=value")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()  # a bare word, e.g. --set simulation.measurement_noise=uniform
        out[key.strip()] = value
    return out


def build_config(config_file: str | None, sets: tuple[str, ...],
                 explicit: dict[str, Any] | None = None) -> Config:
    """The configuration of a command: defaults < ``--config`` < ``--set`` < ``explicit``.

    ``explicit`` maps dotted fields to the values of explicit options; ``None`` values (an
    option not given) are ignored.
    """
    config = Config.from_toml(config_file) if config_file else Config()
    overrides = parse_set(sets)
    overrides.update({k: v for k, v in (explicit or {}).items() if v is not None})
    return config.with_overrides(overrides) if overrides else config


#: Explicit run options and the fields they set.
RUN_FIELDS = {"av": "av.kind", "hv": "hv.kind", "hv_role": "hv.role", "pa": "roles.p_a",
              "pa_hat": "mpc.p_a_hat", "scenario": "scenario.kind", "mode": "mode",
              "shield": "av.shield"}

#: Help of ``--shield`` (one setting).
SHIELD_HELP = ("Safety shield around the AV planner (docs/method.md §12): off, worst-case, "
               "responsive [off in paper mode, worst-case in corrected mode].")


def shield_option(func: Callable) -> Callable:
    """``--shield`` (one setting), setting ``av.shield``."""
    return click.option("--shield", type=click.Choice(list(SHIELD_KINDS)), default=None,
                        help=SHIELD_HELP)(func)


def run_explicit(options: dict[str, Any]) -> dict[str, Any]:
    """The dotted fields set by the run options of :func:`run_options` (given or not)."""
    return {field: options.get(name) for name, field in RUN_FIELDS.items()}


def config_of(options: dict[str, Any]) -> Config:
    """The configuration the run options describe (see the precedence above)."""
    return build_config(options.get("config_file"), options.get("sets", ()),
                        run_explicit(options))


def config_options(func: Callable) -> Callable:
    """``--mode``, ``--config`` and ``--set``."""
    for option in reversed([
        click.option("--mode", type=click.Choice(list(MODES)), default=None,
                     help="paper (quirks Q1..Q7, docs/method.md §9) or corrected [paper]."),
        click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
                     help="TOML file of parameters."),
        click.option("--set", "sets", multiple=True, metavar="SECTION.FIELD=VALUE",
                     help="Override one parameter (repeatable), e.g. mpc.epsilon=0.05."),
    ]):
        func = option(func)
    return func


class _PaHat(click.ParamType):
    """A number or ``online`` (``mpc.p_a_hat``; the range is the configuration's check)."""

    name = "NUMBER|online"

    def convert(self, value, param, ctx):
        if isinstance(value, float) or value == "online":
            return value
        try:
            return float(value)
        except ValueError:
            self.fail(f"{value!r} is neither a number nor online", param, ctx)


PA_HAT = _PaHat()

#: ``--interactions``: repeated interactions with one human per seed.
INTERACTIONS_HELP = ("Repeated interactions with one human per seed (same human, fresh "
                     "initial states; an online AV carries its posterior over p_a; "
                     "docs/method.md §13.9) [1].")


def run_options(seed_default: int = 1, seed_help: str = "Run seed.") -> Callable:
    """The options that define one closed-loop run (shared by simulate, plot and animate)."""
    options = [
        click.option("--av", type=click.Choice([*AV_KINDS, *AV_KIND_ALIASES]), default=None,
                     help="AV planner [persuasive; mpc is its old name]: persuasive, passive, "
                          "cv, lfg (the 2-LFG case), yield (docs/method.md §11)."),
        click.option("--hv", type=click.Choice(list(SIMULATED_HV_KINDS)), default=None,
                     help="Human model [lfg]: lfg, stubborn, noisy, idm, aggressive, replay, "
                          "adversary, deceptive, random."),
        click.option("--shield", type=click.Choice(list(SHIELD_KINDS)), default=None,
                     help=SHIELD_HELP),
        click.option("--hv-role", type=click.Choice(list(ROLES)), default=None,
                     help="HV initial role [leader]."),
        click.option("--pa", type=float, default=None, help="Human's p_a in [0, 1] [1.0]."),
        click.option("--pa-hat", type=PA_HAT, default=None,
                     help="AV's estimate of p_a in [0, 1], or online (a posterior over p_a, "
                          "docs/method.md §13.9) [equal to --pa]."),
        click.option("--scenario", type=click.Choice(list(SCENARIO_KINDS)), default=None,
                     help="Geometry [intersection]: intersection, crossing, left-turn, merge."),
        click.option("--seed", type=int, default=seed_default, show_default=True,
                     help=seed_help),
    ]

    def decorate(func: Callable) -> Callable:
        func = config_options(func)
        for option in reversed(options):
            func = option(func)
        return func

    return decorate


def check_workers(workers: int | None, n_tasks: int) -> int:
    """Worker processes for ``n_tasks`` chunks: default all cores, capped at ``n_tasks``.

    More than 8 processes per core is refused (exit 2); more than the cores gets a warning.
    """
    cores = os.cpu_count() or 1
    if workers is None:
        workers = cores
    if workers > 8 * cores:
        raise ConfigError(f"--workers = {workers} is out of range; allowed: 1..{8 * cores} "
                          f"(8 per core, {cores} cores)")
    if workers > cores:
        click.echo(f"warning: {workers} workers on {cores} cores; runs will share the cores",
                   err=True)
    return max(1, min(workers, n_tasks))


def compile_notice() -> None:
    """One line on stderr when the compiled kernels are not cached yet (first use)."""
    from .._compile import kernels_cached

    if not kernels_cached():
        click.echo("compiling the numerical kernels once (about 25 s; cached for later runs)",
                   err=True)
        sys.stderr.flush()


def progress_bar(quiet: bool, rows: int | None = None) -> Callable[..., None] | None:
    """A progress callback drawing a tqdm bar on stderr (``None`` when ``quiet``):
    ``update(done_runs, total_runs[, rows_done])``, rows shown when ``rows`` is given.

    The bar appears at the first update with runs left (a study resumed with nothing to run
    shows none). ``update.close()`` ends its line: a command calls it when it stops, whether
    it finished or failed, so that an error that follows is printed on a line of its own.
    """
    if quiet:
        return None
    from tqdm import tqdm

    bar: dict[str, Any] = {}

    def update(done: int, total: int, rows_done: int | None = None) -> None:
        if "bar" not in bar:
            if done >= total:
                return  # nothing left to run: no bar
            bar["bar"] = tqdm(total=total, initial=done, unit="run", file=sys.stderr,
                              dynamic_ncols=True, smoothing=0.1)
        b = bar["bar"]
        if rows is not None and rows_done is not None:
            b.set_postfix_str(f"rows {rows_done}/{rows}", refresh=False)
        b.update(done - b.n)
        if done >= total:
            b.close()

    def close() -> None:
        if "bar" in bar:
            bar["bar"].close()

    update.close = close  # type: ignore[attr-defined]
    return update
