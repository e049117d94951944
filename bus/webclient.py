"""One WebSocket client of ``bus/web.py``'s server: a bounded backlog sent in order by one task,
and the close of every client at a node's stop (``close_clients``)."""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Iterable

from aiohttp import WSCloseCode, web

CLOSE_WAIT_S = 0.5      # how long a WebSocket client has to answer the server's close
CLIENT_BACKLOG = 256    # messages waiting for a slow client; past this its oldest are dropped
CLIENT_BACKLOG_BYTES = 8 << 20  # and bytes: 256 large messages must not hold a gigabyte for one client


class WebClient:
    """One WebSocket client: text and binary messages wait in a bounded backlog, sent in
    order by one task (``send_all``); a client ``CLIENT_BACKLOG`` messages (or
    ``CLIENT_BACKLOG_BYTES``) behind loses the oldest, each one told to ``on_drop``.
    Messages pushed ``kept`` (a reply to what the client asked) are never dropped and go
    out before the backlog: whoever pushes them bounds their number (the web pages' server
    stops reading a client whose replies pile up)."""

    def __init__(self, ws: web.WebSocketResponse, on_drop: Callable[[], None],
                 transport: asyncio.BaseTransport | None = None) -> None:
        self.ws = ws
        self.on_drop = on_drop
        self.transport = transport  # cut by close_clients if the client never takes the close
        self.backlog: deque[str | bytes] = deque()
        self.size = 0  # bytes (characters) waiting in the backlog
        self.kept: deque[str | bytes] = deque()
        self.waiting = asyncio.Event()

    def push(self, message: str | bytes, kept: bool = False) -> None:
        if kept:
            self.kept.append(message)
            self.waiting.set()
            return
        self.backlog.append(message)
        self.size += len(message)
        while len(self.backlog) > CLIENT_BACKLOG or (self.size > CLIENT_BACKLOG_BYTES and len(self.backlog) > 1):
            self.size -= len(self.backlog.popleft())
            self.on_drop()
        self.waiting.set()

    async def send_all(self) -> None:
        while not self.ws.closed:
            await self.waiting.wait()
            self.waiting.clear()
            while (self.kept or self.backlog) and not self.ws.closed:
                if self.kept:
                    message = self.kept.popleft()
                else:
                    message = self.backlog.popleft()
                    self.size -= len(message)
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
