"""An asyncio HTTP/WebSocket server (aiohttp) inside an adapter's lifecycle.

The adapter adds routes to ``app``, calls ``start()`` from its ``_start`` (the
port is bound when it returns), and the node's ``stop()`` ends the server: open
WebSocket connections are closed (a bounded wait for each client's answer),
handlers still running are cancelled, and the loop's thread is joined. The loop
runs on a worker made with ``adapter.spawn``, so an exception escaping the
server — a callback on its loop, a task nobody awaits; not a single request's 500 —
fails the node like any dying worker. ``broadcast`` sends a value to every
WebSocket client from any thread (a bus worker, a Zenoh callback).

    self.web = WebServer(self, self.config.host, self.config.port)
    self.web.app.router.add_get("/ws", self.web.websocket)
    self.web.start()
    self.web.broadcast({"v": 0.5})      # from any thread

Nothing on the network can take it down (``Limits``, docs/design.md): connections past
``connections`` get a 503 and are closed; WebSocket clients past ``clients`` a 503; a
connection without a whole request ``timeout_s`` after it opened (a half-sent request,
a slowloris: counted ``timed_out``) or after its last answer (an idle keep-alive: counted
``idle_closed``) is closed (aiohttp's ``keepalive_timeout``, which runs from the
connection's start), and one that reads nothing of what it is sent for ``timeout_s`` is cut
(``stalled``: it would hold its place for ever); request lines and
headers are bounded (aiohttp's ``max_line_size``, ``max_field_size``, ``max_headers``:
400 past them); running out of file descriptors (EMFILE on accept) is counted
``accept_failed`` and warned about, and asyncio accepts again a second later; each
client's backlog is bounded in messages and bytes. With ``browsers``, a request from a
page of another site (``Origin``) or under a name this server does not answer to (``Host``:
DNS rebinding) is refused with 403 (``bus/browser.py``).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import errno
import json
import logging
import os
import resource
import socket
import threading
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from aiohttp import web, web_fileresponse
from aiohttp.http_exceptions import HttpProcessingError

from .browser import OWN, check_browser
from .options import bad
from .webclient import CLIENT_BACKLOG, CLIENT_BACKLOG_BYTES, CLOSE_WAIT_S, WebClient, close_clients
from .webconnection import Refused, TimedHandler

if TYPE_CHECKING:
    from .adapter import Adapter

__all__ = ["CLIENT_BACKLOG", "CLIENT_BACKLOG_BYTES", "Limits", "WebClient", "WebServer", "close_clients"]

log = logging.getLogger(__name__)

START_TIMEOUT_S = 5.0   # binding the port takes milliseconds; this only guards a wedged loop
SHUTDOWN_S = 0.5        # how long running handlers have to finish before they are cancelled
LISTEN_BACKLOG = 128    # connections the kernel holds before accept (aiohttp's default)
MAX_HEADERS = 64        # header lines of one request (aiohttp's default 128); each at most 8190 bytes
# accept() errors that say the process or the machine is out of something: asyncio retries a second later
OUT_OF_RESOURCES = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
FILES_SHARE = 8         # one server holds at most 1/8 of the files the process may open: the rest is the bus's,
                        # the recorder's, the other servers' (1,100 connections under `ulimit -n 1024` ended the show)

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]

# Files (the web node's pages) go through the transport, not sendfile(): a client that reads
# nothing is then seen (the transport pauses writing) and cut after timeout_s; sendfile would
# wait on the socket for ever. The files served are small.
web_fileresponse.NOSENDFILE = True  # type: ignore[misc]


@dataclass(frozen=True)
class Limits:
    """What one server takes at once (``[nodes.<name>.limits]`` of the nodes that serve)."""

    connections: int = 128   # TCP connections open at once (requests, pages, WebSockets); past it: 503, closed
    clients: int = 32        # WebSocket clients at once (within connections); past it: 503
    timeout_s: float = 5.0   # no whole request this long after a connection opened or was last answered: closed

    def __post_init__(self) -> None:
        if not 1 <= self.connections <= 60000:
            raise bad("connections", f"{self.connections} must be in [1, 60000] (and below the process's limit "
                                     "of open files, `ulimit -n`)")
        if not 1 <= self.clients <= 60000:
            raise bad("clients", f"{self.clients} must be in [1, 60000] (each is a connection too)")
        if not 0.1 <= self.timeout_s <= 3600:
            raise bad("timeout_s", f"{self.timeout_s:g} must be in [0.1, 3600] (seconds)")


class WebServer:
    """An aiohttp ``app`` served on ``host:port`` (0: any free port) while ``adapter`` runs,
    within ``limits``; ``browsers``: every request passes ``check_browser`` (pages of ``origins``
    may read it too: ``"*"``, any; ``names``: the ``Host`` names it answers to, ``bus/browser.py``)."""

    def __init__(self, adapter: Adapter, host: str = "127.0.0.1", port: int = 0, key: str = "",
                 limits: Limits = Limits(), browsers: bool = False, origins: tuple[str, ...] = (),
                 names: str = OWN) -> None:
        self.adapter = adapter
        self.key = key  # the configuration key of host:port ("listen"); "": keys 'host' and 'port'
        self.host = host
        self.port = port                   # the bound port once started
        self.limits = limits
        self.origins, self.names = origins, names
        self.app = web.Application(middlewares=[self._errors, *([self._browsers] if browsers else [])])
        self.latest: Any = None            # the last value broadcast (a new WebSocket client gets it first)
        self.dropped = 0                   # messages a slow client missed
        self._latest_text: str | None = None
        self._clients: set[WebClient] = set()
        self._sockets: set[web.WebSocketResponse] = set()  # every route's WebSocket clients (limits.clients)
        self._handlers: Any = None         # aiohttp's protocol factory (web_server.Server)
        self._open = 0                     # connections handed to aiohttp and not lost yet
        self._cap = limits.connections     # limits.connections, within the process's files (FILES_SHARE)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._crash: BaseException | None = None
        self._ended: asyncio.Event | None = None  # (on the loop) the server ends once it is set
        adapter.stats.follow("dropped", lambda: self.dropped)  # the node's stats count them too
        # what the limits refused (below), shown at zero
        adapter.stats.declare(("connections_refused", "clients_refused", "accept_failed", "refused", "timed_out",
                               "idle_closed", "stalled"))

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host  # (an IPv6 address: http://[::1]:8080)
        return f"http://{host}:{self.port}"

    @property
    def clients(self) -> int:
        """How many clients a ``websocket`` route has connected now."""
        return len(self._clients)

    @property
    def connections(self) -> int:
        """How many TCP connections are open now (refused ones aside)."""
        return self._open

    def start(self) -> None:
        """Serve ``app`` on a worker thread of the adapter; return once listening.
        A port that cannot be bound is a ``ConfigError`` naming key 'port' (or ``key``)."""
        self.adapter.spawn(self._serve, "web")
        if not self._ready.wait(START_TIMEOUT_S):
            raise RuntimeError(f"the web server on {self.host}:{self.port} did not start within {START_TIMEOUT_S} s")
        error, host_key, port_key = self._start_error, self.key or "host", self.key or "port"
        if isinstance(error, socket.gaierror):
            raise bad(host_key, f"cannot listen on {self.host!r}: {error.strerror} — "
                              "give an address of this machine (127.0.0.1: this machine only, 0.0.0.0: all)")
        if isinstance(error, OSError):
            reason = os.strerror(error.errno) if error.errno else str(error)
            if error.errno == errno.EADDRNOTAVAIL:
                raise bad(host_key, f"cannot listen on {self.host}:{self.port}: {reason} — {self.host} is not an "
                                  "address of this machine (127.0.0.1: this machine only, 0.0.0.0: all)")
            raise bad(port_key, f"cannot listen on {self.host}:{self.port}: {reason} — "
                              "choose a free port (0: any)")
        if error is not None:
            raise error

    def broadcast(self, value: Any) -> None:
        """Send ``value`` as JSON to every WebSocket client (from any thread); a client
        that falls ``CLIENT_BACKLOG`` messages behind loses the oldest."""
        text = json.dumps(value, allow_nan=False)  # (NaN is no JSON: a browser's JSON.parse refuses it)
        self.latest, self._latest_text = value, text
        self.call(self._push, text)

    def call(self, function: Callable[..., None], *args: Any) -> bool:
        """Run ``function(*args)`` on the server's loop soon (from any thread; a plain callback,
        cheaper than ``submit`` on a per-frame path); nothing when the server is not running
        (False then)."""
        loop = self._loop
        if loop is None:
            return False
        try:
            loop.call_soon_threadsafe(function, *args)
        except RuntimeError:  # the loop has closed: the node is stopping, nobody listens
            return False
        return True

    def submit(self, coro: Coroutine[Any, Any, Any]) -> concurrent.futures.Future[Any]:
        """Run ``coro`` on the server's loop (from another thread); its result or
        exception comes back in the returned future."""
        if self._loop is None:
            coro.close()
            raise RuntimeError(f"the web server of {self.adapter.name!r} is not running")
        return asyncio.run_coroutine_threadsafe(coro, self._loop)

    @contextlib.asynccontextmanager
    async def accept(self, request: web.Request, **options: Any) -> AsyncIterator[web.WebSocketResponse]:
        """The WebSocket of ``request`` (``options``: ``web.WebSocketResponse``'s), prepared, for
        the ``with`` block; past ``limits.clients`` a 503 instead (counted ``clients_refused``)."""
        if len(self._sockets) >= self.limits.clients:
            self.adapter.count("clients_refused")
            self.adapter.warn("clients", f"web server on {self.url}: a WebSocket client from {request.remote} "
                                         f"refused (503): {self.limits.clients} connected already, the most "
                                         "[limits] clients allows")
            raise web.HTTPServiceUnavailable(text=f"503: {self.limits.clients} WebSocket clients connected "
                                                  "already, the most this server takes\n")
        ws = web.WebSocketResponse(timeout=CLOSE_WAIT_S, **options)
        await ws.prepare(request)
        self._sockets.add(ws)
        try:
            yield ws
        finally:
            self._sockets.discard(ws)

    async def serve_client(self, ws: web.WebSocketResponse, client: WebClient,
                           take: Callable[[Any], None] = lambda message: None,
                           room: Callable[[], Awaitable[None]] | None = None) -> None:
        """Run ``client``'s sender while ``ws`` is open, each message it sends to ``take``;
        ``room`` (if given) is awaited before each: the client is not read meanwhile."""
        sender = asyncio.create_task(client.send_all())
        try:
            async for message in ws:
                if room is not None:
                    await room()
                take(message)
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender  # a bug of send_all raises here, not lost in a task nobody reads

    async def websocket(self, request: web.Request) -> web.WebSocketResponse:
        """A route handler: the client gets the latest value, then every broadcast;
        what it sends is ignored."""
        async with self.accept(request) as ws:
            client = WebClient(ws, self._dropped, request.transport)
            self._clients.add(client)
            if self._latest_text is not None:
                client.push(self._latest_text)
            try:
                await self.serve_client(ws, client)
            finally:
                self._clients.discard(client)
        return ws

    # -- on the loop's thread ---------------------------------------------------------

    def _serve(self) -> None:
        asyncio.run(self._main())
        if self._crash is not None:
            raise self._crash

    async def _main(self) -> None:
        loop = asyncio.get_running_loop()
        loop.set_exception_handler(self._on_loop_error)
        # keepalive_timeout runs from a connection's start and is not pushed back by bytes that
        # come: it is the header timeout too (aiohttp >= 3.10)
        runner = web.AppRunner(self.app, handle_signals=False, access_log=None, shutdown_timeout=SHUTDOWN_S,
                               logger=self._request_log(), keepalive_timeout=self.limits.timeout_s,
                               max_headers=MAX_HEADERS)
        listener: asyncio.Server | None = None
        try:
            await runner.setup()
            self._handlers = runner.server
            lost = self._handlers.connection_lost

            def connection_lost(handler: Any, exc: BaseException | None = None) -> None:
                self._open -= 1  # (counted here, not from aiohttp's list: that one is made a loop turn later)
                lost(handler, exc)
            self._handlers.connection_lost = connection_lost
            # (not aiohttp's TCPSite: a connection past the cap must get a protocol of its own)
            listener = await loop.create_server(self._connection, self.host, self.port, backlog=LISTEN_BACKLOG,
                                                reuse_address=True)
        except Exception as exc:  # start() raises it in the adapter's thread
            self._start_error = exc
            self._ready.set()
            await runner.cleanup()
            return
        self.port = listener.sockets[0].getsockname()[1]
        self._cap = self._connection_cap()
        self._loop = loop
        ended = self._ended = asyncio.Event()  # set by the node's stop (when_stopping) or a crash: no poll
        if self._crash is not None:
            ended.set()
        self.adapter.when_stopping(lambda: self.call(ended.set))
        self._ready.set()
        try:
            await ended.wait()
        finally:
            self._loop = None
            listener.close()
            await close_clients(self._clients)
            await runner.cleanup()

    def _connection(self) -> asyncio.Protocol:
        """The protocol of a connection just accepted: aiohttp's, or past ``limits.connections``
        one that answers 503 and closes (counted ``connections_refused``)."""
        if self._open < self._cap:
            self._open += 1
            return TimedHandler(self._handlers, self._timed_out, self._stalled, self.limits.timeout_s,
                            loop=self._handlers._loop, **self._handlers._kwargs)
        self.adapter.count("connections_refused")
        self.adapter.warn("connections", f"web server on {self.url}: {self._cap} connections open, the most it "
                                         "takes ([limits] connections): new ones get 503 and are closed "
                                         f"(a connection without a whole request is closed after "
                                         f"{self.limits.timeout_s:g} s)")
        return Refused()

    def _dropped(self) -> None:
        self.dropped += 1

    def _timed_out(self, requests: int) -> None:
        """A connection closed by ``limits.timeout_s``: before a whole request came (``timed_out``:
        a half-sent request, a slowloris, a connection that never sent) or idle after its answers."""
        self.adapter.count("timed_out" if requests == 0 else "idle_closed")

    def _stalled(self) -> None:
        self.adapter.count("stalled")
        self.adapter.warn("stalled", f"web server on {self.url}: a client that read nothing of what it was sent for "
                                     f"{self.limits.timeout_s:g} s cut ([limits] timeout_s)")

    def _push(self, text: str) -> None:
        for client in self._clients:
            client.push(text)

    def _request_log(self) -> logging.Logger:
        """What aiohttp logs of a request it could not handle (a malformed request line, a
        9,000-byte path: a port scanner on the LAN) as one rate-limited line instead of a
        traceback, what the client sent wrong counted ``bad``."""
        requests = logging.Logger(f"sonibus.web.{self.adapter.name}")  # (not registered: nothing else logs here)

        def one_line(record: logging.LogRecord) -> bool:
            exc = record.exc_info[1] if record.exc_info else None
            if record.levelno < logging.WARNING and exc is None:
                return False
            refused = isinstance(exc, HttpProcessingError)
            if refused:  # (a handler's own failure was counted by the _errors middleware on its way out)
                self.adapter.count("bad")
            what = f"{type(exc).__name__}: {' '.join(str(exc).split())[:160]}" if exc else ""  # (aiohttp's: lines)
            self.adapter.warn("http-refused" if refused else "http",
                              f"web server: {record.getMessage()}{f': {what}' if what else ''}")
            return False

        requests.addFilter(one_line)
        return requests

    def _connection_cap(self) -> int:
        """``limits.connections``, lowered (and said) past 1/``FILES_SHARE`` of the files the
        process may open: connections must never take the files the rest of the show needs."""
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        share = max(4, soft // FILES_SHARE) if soft != resource.RLIM_INFINITY else self.limits.connections
        if self.limits.connections <= share:
            return self.limits.connections
        log.warning("%s: web server on %s: [limits] connections = %d lowered to %d: this process may open %d "
                    "files (ulimit -n), and one server takes at most 1/%d of them — raise the limit to take more",
                    self.adapter.name, self.url, self.limits.connections, share, soft, FILES_SHARE)
        return share

    def _on_loop_error(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        exc = context.get("exception")
        if isinstance(exc, OSError) and exc.errno in OUT_OF_RESOURCES:  # accept(): asyncio tries again in 1 s
            self.adapter.count("accept_failed")
            soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
            self.adapter.warn("accept", f"web server on {self.url}: cannot accept a connection: {exc.strerror} "
                                        f"({self.connections} connections open here, the process may open {soft} "
                                        "files) — retrying every second; raise the limit (ulimit -n) or lower "
                                        "[limits] connections")
            return
        if not isinstance(exc, Exception) or self.adapter.stopping.is_set():
            # a message without an exception ("Unclosed client session"), or noise of a stop: said, not fatal
            self.adapter.count("errors")
            self.adapter.warn("loop", f"web server: {context.get('message', 'loop error')}"
                                      f"{f': {exc}' if exc is not None else ''}")
            return
        if self._crash is None:  # the worker raises it: fail() logs it with its traceback
            self._crash = exc
            if self._ended is not None:
                self._ended.set()

    @web.middleware
    async def _errors(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        """A request whose handler raises gets a 500, counted in ``errors`` and warned
        about (one line, at most every few seconds); the server goes on."""
        try:
            return await handler(request)
        except web.HTTPException:
            raise
        except Exception as exc:
            self.adapter.count("errors")
            if request.writer.output_size > 0:  # a response under way (a WebSocket) cannot become a 500:
                raise                           # aiohttp logs it and cuts the connection
            self.adapter.warn("http", f"{request.method} {request.path} failed: {type(exc).__name__}: {exc}")
            raise web.HTTPInternalServerError() from None

    @web.middleware
    async def _browsers(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        """``check_browser`` on every request: a refusal is a 403, counted ``refused``."""
        reason = check_browser(request, self.origins, self.names)
        if reason:
            self.adapter.count("refused")
            self.adapter.warn("refused", f"web server: refused {request.method} {request.path[:80]} from "
                                         f"{request.remote}: {reason}")
            raise web.HTTPForbidden(text=f"403 forbidden: {reason}\n")
        return await handler(request)
