"""The ``persuasive`` command line.

Each command lives in its own module of this package and is added to the :func:`cli` group
here; the modules share only :mod:`persuasive.cli._common` (configuration precedence, run
options, worker and output checks), so each imports on its own. Bad input ends a command with
one line on stderr (``error: ...``) and exit status 2; nothing already written is touched, and
results are written to temporary files (or folders) first, then renamed.
"""

from __future__ import annotations

import sys

import click

from .._version import __version__
from ..config import ConfigError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="persuasive")
def cli() -> None:
    """Persuasive trajectory planning with an adaptive leader-follower game."""


def _register() -> None:
    from .bench import bench
    from .compare import compare
    from .drive import drive
    from .fit import fit
    from .highway import highway
    from .plots import animate, plot, plot_compare
    from .reproduce import reproduce
    from .simulate import simulate
    from .sumo import sumo
    from .sweep import plot_sweep, sweep

    for command in (simulate, reproduce, compare, sweep, bench, plot, animate, drive):
        cli.add_command(command)
    cli.add_command(highway)
    cli.add_command(fit)
    cli.add_command(sumo)
    plot.add_command(plot_sweep)
    plot.add_command(plot_compare)


_register()


#: Raised by click 8.2 and later for a group called without a command (click 8.1 prints the
#: help and exits 0 itself).
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


def main(argv: list[str] | None = None) -> int:
    """Entry point: one-line errors, exit status 2 for bad input; a group without a command
    (``persuasive``, ``persuasive plot``) prints its help and exits 0."""
    try:
        rv = cli.main(args=argv, prog_name="persuasive", standalone_mode=False)
    except _NO_ARGS_IS_HELP as exc:
        click.echo(exc.ctx.get_help())
        return 0
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
        where = f": {exc.filename}" if exc.filename else ""
        click.echo(f"error: {(exc.strerror or str(exc)).lower()}{where}", err=True)
        return 2
    return rv if isinstance(rv, int) else 0


__all__ = ["cli", "main"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
