"""The ``persuasive`` command line.

Each command lives in its own module of this package and is added to the :func:`cli` group
here; the modules share only :mod:`persuasive.cli._common` (configuration precedence, run
options, worker and output checks), so each imports on its own. Bad input ends a command with
one line on stderr (``error: ...``) and exit status 2; nothing already written is touched, and
results are written to temporary files (or folders) first, then renamed.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import threading
from typing import Iterator

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
    from .compile import compile_command
    from .drive import drive
    from .fit import fit
    from .highway import highway
    from .junction import junction
    from .plots import animate, plot, plot_compare
    from .recordings import recordings
    from .reproduce import reproduce
    from .simulate import simulate
    from .sumo import sumo
    from .sweep import plot_sweep, sweep

    for command in (simulate, reproduce, compare, sweep, bench, plot, animate, drive):
        cli.add_command(command)
    cli.add_command(highway)
    cli.add_command(fit)
    cli.add_command(sumo)
    cli.add_command(junction)
    cli.add_command(recordings)
    cli.add_command(compile_command)
    plot.add_command(plot_sweep)
    plot.add_command(plot_compare)


_register()


#: Raised by click 8.2 and later for a group called without a command (click 8.1 prints the
#: help and exits 0 itself).
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


class _Compiling:
    """How deep this thread is in Numba's compiler lock (a listener of its events)."""

    depth = 0
    installed = False

    @classmethod
    def _started(cls) -> None:
        if threading.current_thread() is threading.main_thread():
            cls.depth += 1

    @classmethod
    def _ended(cls) -> None:
        if threading.current_thread() is threading.main_thread():
            cls.depth = max(0, cls.depth - 1)

    @classmethod
    def install(cls) -> None:
        if not cls.installed:
            from .._compile import listen

            listen("numba:compiler_lock", cls._started, cls._ended)
            cls.installed = True


def _on_interrupt(signum, frame) -> None:
    """Ctrl-C: a KeyboardInterrupt, which every command turns into one line and exit 130
    (its workers killed at once, its temporary files removed). Inside a kernel compile (which
    would swallow the interrupt in LLVM's callbacks, or break half-way with a traceback) and
    at a second Ctrl-C, the command ends at once instead: the same line, its scratch folder
    removed, exit 130 (its workers end with it; the kernel cache is written atomically, so
    an interrupted compile only compiles again next time)."""
    _on_interrupt.count = getattr(_on_interrupt, "count", 0) + 1
    if _on_interrupt.count > 1 or _Compiling.depth > 0:
        sys.stderr.write("\nerror: interrupted\n")
        sys.stderr.flush()
        from .._processes import remove_scratch

        remove_scratch()
        os._exit(130)
    # the command stops: what Dask and tornado log while it tears down (a cancelled gather,
    # a callback of the interrupted wait) is noise, not the one line the user gets
    logging.disable(logging.CRITICAL)
    raise KeyboardInterrupt


@contextlib.contextmanager
def _interruptible() -> Iterator[None]:
    """:func:`_on_interrupt` for Ctrl-C while a command runs in the main thread (the previous
    handler is put back afterwards, e.g. when a test calls :func:`main`)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _Compiling.install()
    _on_interrupt.count = 0
    previous = signal.signal(signal.SIGINT, _on_interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if _on_interrupt.count:
            logging.disable(logging.NOTSET)


def _interrupted(exc: BaseException) -> bool:
    """True when ``exc`` is, or was raised while handling, a KeyboardInterrupt (a library's
    cleanup may turn one into another error)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    """Entry point: one-line errors, exit status 2 for bad input, 130 for Ctrl-C; a group
    without a command (``persuasive``, ``persuasive plot``) prints its help and exits 0."""
    try:
        with _interruptible():
            rv = cli.main(args=argv, prog_name="persuasive", standalone_mode=False)
    except _NO_ARGS_IS_HELP as exc:
        click.echo(exc.ctx.get_help())
        return 0
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("error: interrupted", err=True)
        return 130
    except click.ClickException as exc:
        click.echo(f"error: {exc.format_message()}", err=True)
        return exc.exit_code
    except ConfigError as exc:
        click.echo(f"error: {exc}", err=True)
        return 2
    except OSError as exc:
        if _interrupted(exc):
            click.echo("error: interrupted", err=True)
            return 130
        where = f": {exc.filename}" if exc.filename else ""
        click.echo(f"error: {(exc.strerror or str(exc)).lower()}{where}", err=True)
        return 2
    except Exception as exc:
        if _interrupted(exc):  # an interrupt a library's cleanup turned into another error
            click.echo("error: interrupted", err=True)
            return 130
        raise
    return rv if isinstance(rv, int) else 0


__all__ = ["cli", "main"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
