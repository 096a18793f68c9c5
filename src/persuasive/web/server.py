"""The web server of ``persuasive drive``: a Starlette app served by uvicorn.

Routes: ``/`` the page, ``/static/<name>`` its script and style sheet, ``/ws`` the session's
websocket (``persuasive.web.session``). Nothing else exists; in particular no path ever reaches
the file system: the static files are read once from the installed package
(``importlib.resources``) into a fixed table, and a name outside it (``..``, ``%2f``, an
absolute path, ...) is a 404.

**Security.** :class:`Guard` wraps the app:

- a server bound to a loopback address (the default, ``127.0.0.1``) answers only requests whose
  ``Host`` is a loopback name (``localhost``, ``127.x.x.x``, ``[::1]``), against DNS rebinding;
- a server bound to any other address requires a token: :func:`create_app` refuses to build
  such an app without one (``ConfigError``), ``persuasive drive`` generates it with
  ``secrets.token_urlsafe`` and prints it in the URL (``?token=...``); every request and
  websocket without the right token gets 403 (compared in constant time);
- a websocket opened by a page of another origin (its ``Origin`` header names another host) is
  refused (403): websockets are not covered by the browser's same-origin rule, so without this
  any web page the researcher visits could drive the study server;
- responses carry a strict Content-Security-Policy (the page loads only its own script and
  style and connects only to its own origin), ``nosniff``, ``no-referrer`` (the token must not
  leak in a Referer header) and ``no-store``.

Messages over :data:`WS_MAX_BYTES` close that connection (its trial is saved as partial);
shorter malformed ones are dropped and counted by the session.

**Shutdown.** On Ctrl-C (SIGINT) or SIGTERM uvicorn closes every websocket (code 1012); each
session saves its open trial as ``-partial`` and writes its summary, and the lifespan's
shutdown saves any session still open. A second Ctrl-C forces the exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import ipaddress
import logging
import secrets
import socket
import threading
import time
from pathlib import Path
from urllib.parse import parse_qs, quote, urlsplit

from ..config import ConfigError
from .session import Hub, Session
from .study import Study

log = logging.getLogger("persuasive.web")

#: The files under ``/static/`` and their media types; nothing else is served.
STATIC_FILES = {"drive.js": "text/javascript; charset=utf-8",
                "drive.css": "text/css; charset=utf-8"}
#: Largest websocket message accepted before the connection is closed [bytes].
WS_MAX_BYTES = 256 * 1024
#: Sessions served at once; more are refused (websocket close 1013, try again later).
MAX_SESSIONS = 64
SECURITY_HEADERS = [
    (b"content-security-policy",
     b"default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
     b"connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"cache-control", b"no-store"),
    (b"x-frame-options", b"DENY"),
]


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address, IPv6 with or without brackets) is loopback."""
    name = host.strip().strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def _host_name(host_header: str) -> str:
    """The host part of a ``Host`` header (``[::1]:8765`` -> ``::1``)."""
    h = host_header.strip()
    if h.startswith("["):
        return h[1:h.find("]")] if "]" in h else h
    return h.rsplit(":", 1)[0] if h.count(":") == 1 else h


def _static_files() -> dict[str, bytes]:
    from importlib.resources import files

    root = files("persuasive.web").joinpath("static")
    return {name: root.joinpath(name).read_bytes() for name in (*STATIC_FILES, "index.html")}


class Guard:
    """ASGI middleware: the token, the loopback ``Host`` rule, the websocket ``Origin`` rule
    and the security headers (see the module docstring)."""

    def __init__(self, app, token: str | None, loopback_only: bool):
        self.app = app
        self.token = token
        self.loopback_only = loopback_only

    def refusal(self, scope) -> str | None:
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in scope.get("headers", [])}
        if self.token is not None:
            query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
            given = query.get("token", [""])[0]
            if not secrets.compare_digest(given.encode("utf-8", "replace"),
                                          self.token.encode("utf-8")):
                return "a valid token is required"
        host = headers.get("host", "")
        if self.loopback_only and not is_loopback(_host_name(host)):
            return "this server answers only on its loopback address"
        if scope["type"] == "websocket":
            origin = headers.get("origin")
            if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
                return "websocket from another origin"
        return None

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        reason = self.refusal(scope)
        if reason is not None:
            log.debug("refused %s %s: %s", scope["type"], scope.get("path"), reason)
            if scope["type"] == "websocket":
                await receive()  # websocket.connect
                await send({"type": "websocket.close", "code": 1008})
                return
            body = f"403 Forbidden: {reason}\n".encode()
            await send({"type": "http.response.start", "status": 403,
                        "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                    (b"content-length", str(len(body)).encode()),
                                    *SECURITY_HEADERS]})
            await send({"type": "http.response.body", "body": body})
            return
        if scope["type"] == "http":
            async def send_with_headers(message):
                if message["type"] == "http.response.start":
                    message = {**message, "headers": [*message.get("headers", []),
                                                       *SECURITY_HEADERS]}
                await send(message)

            await self.app(scope, receive, send_with_headers)
            return
        await self.app(scope, receive, send)


def create_app(study: Study, out_dir: str | Path, token: str | None = None,
               host: str = "127.0.0.1") -> Guard:
    """The ASGI app serving ``study`` for the address ``host`` (see the module docstring).

    ``out_dir`` must exist. A non-loopback ``host`` without a ``token`` is refused with a
    :class:`ConfigError`. The returned app has the sessions' :class:`Hub` as ``app.hub``.
    """
    from starlette.applications import Starlette
    from starlette.responses import HTMLResponse, PlainTextResponse, Response
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocket

    loopback = is_loopback(host)
    if not loopback and not token:
        raise ConfigError(f"--host {host} is not a loopback address: the server needs a "
                          "token there (persuasive drive generates one); refusing to serve "
                          "without it")
    if token is not None and (len(token) < 16 or not all(c.isalnum() or c in "-_"
                                                         for c in token)):
        raise ConfigError("token must be at least 16 characters [A-Za-z0-9_-]")
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise ConfigError(f"output folder {str(out_dir)!r} does not exist")
    hub = Hub(study, out_dir)
    files = _static_files()
    query = f"?token={quote(token)}" if token else ""
    page = files["index.html"].decode("utf-8").replace("{{QUERY}}", html.escape(query))

    async def index(request) -> Response:
        return HTMLResponse(page)

    async def static(request) -> Response:
        name = request.path_params["name"]
        if name not in STATIC_FILES:
            return PlainTextResponse("404 Not Found\n", status_code=404)
        return Response(files[name], media_type=STATIC_FILES[name])

    async def websocket(ws: WebSocket) -> None:
        if len(hub.sessions) >= MAX_SESSIONS:
            await ws.close(code=1013)
            return
        await ws.accept()
        session = Session(hub, ws.send_text)
        session.start()
        reason = "disconnected"
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    if message.get("code") == 1012:  # uvicorn closes every socket on shutdown
                        reason = "server-shutdown"
                    break
                if message["type"] == "websocket.receive":
                    session.receive(message.get("text"), message.get("bytes"))
        except Exception:  # noqa: BLE001 - a broken connection ends only this session
            log.debug("websocket failed", exc_info=True)
        finally:
            await session.close(reason)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        await hub.close_all("server-shutdown")

    app = Starlette(routes=[Route("/", index), Route("/static/{name}", static),
                            WebSocketRoute("/ws", websocket)], lifespan=lifespan)
    guard = Guard(app, token, loopback)
    guard.hub = hub
    return guard


# -- running it ----------------------------------------------------------------------------------


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (``port`` 0: any free port); a
    :class:`ConfigError` naming the address when it cannot be had."""
    try:
        infos = socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ConfigError(f"--host {host!r} cannot be resolved: {exc.strerror}") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise ConfigError(f"cannot listen on {host}:{port}: "
                          f"{(exc.strerror or str(exc)).lower()}") from None
    sock.setblocking(False)
    return sock


def url_of(sock: socket.socket, host: str, token: str | None,
           participant: str | None = None) -> str:
    """The page's URL for a listening socket (the machine's name for a wildcard bind)."""
    port = sock.getsockname()[1]
    name = host.strip("[]")
    if name in ("0.0.0.0", "::", ""):
        name = socket.gethostname()
    if ":" in name:
        name = f"[{name}]"
    params = []
    if participant:
        params.append(f"participant={quote(participant)}")
    if token:
        params.append(f"token={quote(token)}")
    return f"http://{name}:{port}/" + ("?" + "&".join(params) if params else "")


def warm_up(study: Study) -> float:
    """Build every condition's world (with its seed) and take a few steps, so that the first
    participant does not wait for the compiled kernels to load and a condition whose initial
    state cannot be drawn fails now; returns the time taken [s]."""
    from ..world import PythonWorld
    from .human import LiveHuman
    from .scene import scene_of

    t0 = time.perf_counter()
    for condition in ((study.practice,) if study.practice else ()) + study.conditions:
        try:
            world = PythonWorld(condition.config, condition.seed, hv=LiveHuman())
        except ConfigError as exc:
            raise ConfigError(f"condition {condition.name!r} (seed {condition.seed}): {exc}") \
                from None
        scene_of(world.scenario, world.states[0], world.n_steps)
        for _ in range(min(3, world.n_steps)):
            world.step()
        world.record()
    return time.perf_counter() - t0


def uvicorn_server(app, log_level: str = "warning"):
    """The uvicorn server for ``app`` (websockets, small frames, no compression)."""
    import uvicorn

    config = uvicorn.Config(app, log_level=log_level, access_log=False, lifespan="on",
                            ws="websockets-sansio", ws_max_size=WS_MAX_BYTES,
                            ws_per_message_deflate=False, timeout_graceful_shutdown=5,
                            server_header=False)
    return uvicorn.Server(config)


class DriveServer:
    """A server running in a background thread (tests, benchmarks): :meth:`start`,
    :attr:`url`, :meth:`stop`. Signal handlers are not installed off the main thread."""

    def __init__(self, app: Guard, sock: socket.socket, host: str = "127.0.0.1",
                 token: str | None = None):
        self.app, self.sock, self.host, self.token = app, sock, host, token
        self.server = uvicorn_server(app)
        self.thread = threading.Thread(target=self._run, name="persuasive-drive", daemon=True)
        self.error: BaseException | None = None

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    @property
    def url(self) -> str:
        return url_of(self.sock, self.host, self.token)

    def _run(self) -> None:
        try:
            asyncio.run(self.server.serve(sockets=[self.sock]))
        except BaseException as exc:  # noqa: BLE001 - reported by start/stop
            self.error = exc

    def start(self, timeout_s: float = 30.0) -> DriveServer:
        self.thread.start()
        t_end = time.monotonic() + timeout_s
        while not self.server.started:
            if self.error is not None or not self.thread.is_alive():
                raise RuntimeError(f"the drive server did not start: {self.error!r}")
            if time.monotonic() > t_end:
                raise RuntimeError("the drive server did not start in time")
            time.sleep(0.02)
        return self

    def stop(self, timeout_s: float = 15.0) -> None:
        self.server.should_exit = True
        self.thread.join(timeout_s)


__all__ = ["DriveServer", "Guard", "bind", "create_app", "is_loopback", "url_of", "warm_up"]
