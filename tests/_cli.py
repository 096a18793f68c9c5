"""Running one command of ``persuasive``'s command line in a test (shared by the CLI tests)."""

from __future__ import annotations

from persuasive.cli import main

#: The one-line notice of the first compilation (a fresh clone's first command) and the line
#: with its time: not part of any command's output.
COMPILE_NOTICE = "compiling the numerical kernels once"
COMPILED = "compiled the numerical kernels in"


def run_cli(capsys, *args) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of ``persuasive ARGS`` (each argument as ``str``), stderr
    without the first-compilation notice and its time."""
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    err = "".join(line for line in err.splitlines(keepends=True)
                  if not line.startswith((COMPILE_NOTICE, COMPILED)))
    return code, out, err
