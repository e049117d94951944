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
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import errno
import json
import logging
import os
import socket
import threading
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Iterable
from typing import TYPE_CHECKING, Any

from aiohttp import WSCloseCode, web
from aiohttp.http_exceptions import HttpProcessingError

from .options import bad

if TYPE_CHECKING:
    from .adapter import Adapter

START_TIMEOUT_S = 5.0   # binding the port takes milliseconds; this only guards a wedged loop
CLOSE_WAIT_S = 0.5      # how long a WebSocket client has to answer the server's close
SHUTDOWN_S = 0.5        # how long running handlers have to finish before they are cancelled
STOP_POLL_S = 0.05      # ``adapter.stopping`` is a threading.Event: the loop looks at it this often
CLIENT_BACKLOG = 256    # messages waiting for a slow client; past this its oldest are dropped

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


class WebServer:
    """An aiohttp ``app`` served on ``host:port`` (0: any free port) while ``adapter`` runs."""

    def __init__(self, adapter: Adapter, host: str = "127.0.0.1", port: int = 0, key: str = "") -> None:
        self.adapter = adapter
        self.key = key  # the configuration key of host:port ("listen"); "": keys 'host' and 'port'
        self.host = host
        self.port = port                   # the bound port once started
        self.app = web.Application(middlewares=[self._errors])
        self.latest: Any = None            # the last value broadcast (a new WebSocket client gets it first)
        self.dropped = 0                   # messages a slow client missed
        self._latest_text: str | None = None
        self._clients: set[WebClient] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._crash: BaseException | None = None
        adapter.stats.follow("dropped", lambda: self.dropped)  # the node's stats count them too

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host  # (an IPv6 address: http://[::1]:8080)
        return f"http://{host}:{self.port}"

    @property
    def clients(self) -> int:
        """How many clients a ``websocket`` route has connected now."""
        return len(self._clients)

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

    def call(self, function: Callable[..., None], *args: Any) -> None:
        """Run ``function(*args)`` on the server's loop soon (from any thread; a plain callback,
        cheaper than ``submit`` on a per-frame path); nothing when the server is not running."""
        loop = self._loop
        if loop is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop has closed: the node is stopping, nobody listens
            loop.call_soon_threadsafe(function, *args)

    def submit(self, coro: Coroutine[Any, Any, Any]) -> concurrent.futures.Future[Any]:
        """Run ``coro`` on the server's loop (from another thread); its result or
        exception comes back in the returned future."""
        if self._loop is None:
            coro.close()
            raise RuntimeError(f"the web server of {self.adapter.name!r} is not running")
        return asyncio.run_coroutine_threadsafe(coro, self._loop)

    async def websocket(self, request: web.Request) -> web.WebSocketResponse:
        """A route handler: the client gets the latest value, then every broadcast;
        what it sends is ignored."""
        ws = web.WebSocketResponse(timeout=CLOSE_WAIT_S)
        await ws.prepare(request)
        client = WebClient(ws, self._dropped, request.transport)
        self._clients.add(client)
        if self._latest_text is not None:
            client.push(self._latest_text)
        sender = asyncio.create_task(client.send_all())
        try:
            async for _ in ws:
                pass
        finally:
            self._clients.discard(client)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender  # a bug of send_all raises here, not lost in a task nobody reads
        return ws

    # -- on the loop's thread ---------------------------------------------------------

    def _serve(self) -> None:
        asyncio.run(self._main())
        if self._crash is not None:
            raise self._crash

    async def _main(self) -> None:
        loop = asyncio.get_running_loop()
        loop.set_exception_handler(self._on_loop_error)
        runner = web.AppRunner(self.app, handle_signals=False, access_log=None, shutdown_timeout=SHUTDOWN_S,
                               logger=self._request_log())
        try:
            await runner.setup()
            site = web.TCPSite(runner, self.host, self.port)
            await site.start()
        except Exception as exc:  # start() raises it in the adapter's thread
            self._start_error = exc
            self._ready.set()
            await runner.cleanup()
            return
        self.port = runner.addresses[0][1]
        self._loop = loop
        self._ready.set()
        try:
            while self._crash is None and not self.adapter.stopping.is_set():
                await asyncio.sleep(STOP_POLL_S)
        finally:
            self._loop = None
            await close_clients(self._clients)
            await runner.cleanup()

    def _dropped(self) -> None:
        self.dropped += 1

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
            what = f"{type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''}" if exc else ""
            self.adapter.warn("http-refused" if refused else "http",
                              f"web server: {record.getMessage()}{f': {what}' if what else ''}")
            return False

        requests.addFilter(one_line)
        return requests

    def _on_loop_error(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        exc = context.get("exception")
        if not isinstance(exc, Exception) or self.adapter.stopping.is_set():
            # a message without an exception ("Unclosed client session"), or noise of a stop: said, not fatal
            self.adapter.count("errors")
            self.adapter.warn("loop", f"web server: {context.get('message', 'loop error')}"
                                      f"{f': {exc}' if exc is not None else ''}")
            return
        if self._crash is None:  # the worker raises it: fail() logs it with its traceback
            self._crash = exc

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


class WebClient:
    """One WebSocket client: text and binary messages wait in a bounded backlog, sent in
    order by one task (``send_all``); a client ``CLIENT_BACKLOG`` behind loses the oldest,
    each one told to ``on_drop``. Messages pushed ``kept`` (a reply to what the client
    asked) are never dropped and go out before the backlog: whoever pushes them bounds
    their number (the web pages' server stops reading a client whose replies pile up)."""

    def __init__(self, ws: web.WebSocketResponse, on_drop: Callable[[], None],
                 transport: asyncio.BaseTransport | None = None) -> None:
        self.ws = ws
        self.on_drop = on_drop
        self.transport = transport  # cut by close_clients if the client never takes the close
        self.backlog: deque[str | bytes] = deque(maxlen=CLIENT_BACKLOG)
        self.kept: deque[str | bytes] = deque()
        self.waiting = asyncio.Event()

    def push(self, message: str | bytes, kept: bool = False) -> None:
        if kept:
            self.kept.append(message)
        else:
            if len(self.backlog) == self.backlog.maxlen:
                self.on_drop()
            self.backlog.append(message)
        self.waiting.set()

    async def send_all(self) -> None:
        while not self.ws.closed:
            await self.waiting.wait()
            self.waiting.clear()
            while (self.kept or self.backlog) and not self.ws.closed:
                message = self.kept.popleft() if self.kept else self.backlog.popleft()
                try:
                    if isinstance(message, bytes):
                        await self.ws.send_bytes(message)
                    else:
                        await self.ws.send_str(message)
                except ConnectionError:  # the client went away; its handler ends the connection
                    return


async def close_clients(clients: Iterable[WebClient]) -> None:
    """Close every client's WebSocket ("going away"), waiting a bounded time for them; the
    connection of one that does not read (its send blocked, the close never taken) is cut,
    or the node's stop would wait on it."""
    clients = list(clients)
    closing = [asyncio.create_task(c.ws.close(code=WSCloseCode.GOING_AWAY, message=b"node stopping"))
               for c in clients]
    if closing:
        await asyncio.wait(closing, timeout=2 * CLOSE_WAIT_S)
    for client in clients:
        if client.transport is not None and not client.transport.is_closing():
            client.transport.abort()
