"""``persuasive drive``: serve the study page where a person drives the HV against the AV.

Binds to loopback (``127.0.0.1``) unless ``--host`` says otherwise. Any other address needs a
token: one is generated (``secrets.token_urlsafe``), printed in the URL, and required on every
request and websocket (403 without it); a warning says the page is reachable from the network.
The study's configurations are checked and the planner's kernels loaded before the URL is
printed. Ctrl-C stops the server cleanly: open trials are saved as ``-partial``, and the
command exits with status 130, as every command stopped by Ctrl-C does.
"""

from __future__ import annotations

import logging
import sys

import click

from ._common import SEED_MAX, Count, compile_notice, lock_output, shield_option

#: Where trials go unless ``--out`` says otherwise.
DEFAULT_OUT = "results/drive"


def _need_web_extra() -> None:
    from ..config import ConfigError

    missing = []
    for module in ("starlette", "uvicorn", "websockets"):
        try:
            __import__(module)
        except ImportError:
            missing.append(module)
    if missing:
        raise ConfigError(f"persuasive drive needs {', '.join(missing)}: install the web "
                          "extra (pip install -e '.[web]' in the persuasive checkout)")


@click.command()
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on. Loopback by default; any other address (e.g. "
                   "0.0.0.0 for a lab network) gets a generated token, printed in the URL, "
                   "that every request must carry (403 without it).")
@click.option("--port", type=Count(0, 65535), default=8765, show_default=True,
              help="Port (0: any free port).")
@click.option("--study", "study_file", type=click.Path(dir_okay=False), default=None,
              help="Study file (TOML): consent, conditions, questions [built-in study].")
@click.option("--out", default=DEFAULT_OUT, show_default=True,
              type=click.Path(file_okay=False),
              help="Folder for the trials and study summaries (created if missing).")
@click.option("--seed", type=Count(0, SEED_MAX), default=None,
              help="Base seed (practice uses it, condition j seed + 1 + j) [the study's].")
@shield_option
def drive(host: str, port: int, study_file: str | None, out: str, seed: int | None,
          shield: str | None) -> None:
    """Drive the HV against the AV's planner in a browser (a user-study server)."""
    import asyncio
    import secrets
    from pathlib import Path

    from .._files import OutputError, check_output_folder
    from ..web.study import default_study, load_study

    _need_web_extra()
    from ..web.server import bind, create_app, is_loopback, url_of, uvicorn_server, warm_up

    study = load_study(study_file) if study_file else default_study()
    if seed is not None:
        study = study.with_seed(seed)
    if shield is not None:
        study = study.with_shield(shield)
    out_dir = check_output_folder(out, "output folder")
    lock_output(out_dir, "output folder")  # one server per folder, until it stops
    loopback = is_loopback(host)
    token = None if loopback else secrets.token_urlsafe(24)
    sock = bind(host, port)  # a bad host or a port in use fails here, before anything is made
    try:
        compile_notice()
        warm_up(study)
        try:  # only now, when the server can start
            Path(out_dir).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"output folder {out!r} cannot be created: "
                              f"{(exc.strerror or str(exc)).lower()}") from None
        app = create_app(study, out_dir, token, host)

        logger = logging.getLogger("persuasive.web")  # one line per session event, on stderr
        if not any(getattr(h, "_persuasive_drive", False) for h in logger.handlers):
            handler = logging.StreamHandler(sys.stderr)
            handler.setFormatter(logging.Formatter("%(asctime)s %(message)s", "%H:%M:%S"))
            handler._persuasive_drive = True
            logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False

        n = len(study.conditions)
        click.echo(f"study: {study.title} ({study.source}); {n} condition{'s' * (n != 1)}"
                   f"{' + practice' if study.practice else ''}; trials go to {out_dir}")
        if not loopback:
            click.echo(f"warning: listening on {host}, not a loopback address: anyone who can "
                       "reach this machine and has the token can open the page; share the URL "
                       "only with participants", err=True)
        click.echo(f"open {url_of(sock, host, token)} in a browser "
                   "(add participant=ID to the query to fill in the ID); Ctrl-C stops")
        sys.stdout.flush()
        server = uvicorn_server(app)
        interrupted = False
        try:
            asyncio.run(server.serve(sockets=[sock]))
        except KeyboardInterrupt:  # uvicorn re-raises the Ctrl-C it handled, after a clean
            interrupted = True     # shutdown (open trials saved as -partial)
    finally:
        sock.close()
    files = sorted(p.name for p in Path(out_dir).glob("*.parquet"))
    click.echo(f"stopped; {len(files)} trial file{'s' * (len(files) != 1)} in {out_dir}")
    if interrupted:  # as every command stopped by Ctrl-C: exit status 130
        click.get_current_context().exit(130)
