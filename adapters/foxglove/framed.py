"""A WebSocket client that is written whole frames, several in one transport write, rather
than one ``send`` per message (issue 35): what the Foxglove hub and the OSCQuery server
stream to their clients. Built on ``bus/web.py``'s ``WebClient`` (its bounded backlog, its
sender task run by ``WebServer.serve_client``); each message is framed here
(``wire.frame_header``: a server's unmasked frame, as aiohttp writes it, so the client
reads the same WebSocket messages), and aiohttp's own frames (pings, pongs, the close)
go between whole frames, never inside one. A connection it serves is accepted without
compression (``compress=False``): the frames are written as they are.

What is due at once goes in one write when nothing waits before it and the socket takes it
(``put_frames``, no wake-up of the sender); otherwise the sender writes what waits up to
``WRITE_BYTES`` at a time and waits for the client to take it when its socket is full.

``Handoff`` brings the frames a node's clients are sent to the server's loop, served there
(the Foxglove node's; OSCQuery's did not gain by it: its frames' work is small, and 3-6 %
more CPU was measured than serving them on Zenoh's threads).

(Their place is ``bus/web.py``, beside ``WebClient``, once the core takes them; the client
is shared by the two adapters that stream.)
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable
from threading import Lock
from typing import Any

from aiohttp import web

from sonibus.bus.queue import item_size
from sonibus.bus.web import CLIENT_BACKLOG, CLIENT_BACKLOG_BYTES, WebClient, WebServer

from . import wire

WRITE_BYTES = 64 << 10  # bytes of a client's messages written in one go (then its socket's room is checked)


class FramedClient(WebClient):
    """What a client is due waits in its backlog as WebSocket frames in parts (parts shared
    by several clients are not copied), bounded as ``WebClient``'s (the oldest dropped, each
    told to ``on_drop``); ``on_write`` is called before each transport write."""

    def __init__(self, ws: web.WebSocketResponse, on_drop: Callable[[], None], request: web.Request,
                 on_write: Callable[[], None] = lambda: None) -> None:
        super().__init__(ws, on_drop, request.transport)
        self.on_write = on_write
        self.protocol = request.protocol  # (its flow control: paused while the socket's buffer is full)
        self.backlog: deque[tuple[int, tuple[bytes, ...]]] = deque()  # type: ignore[assignment]  # (size, parts)

    def push(self, message: str | bytes, kept: bool = False) -> None:
        """A text (``str``) or binary message, framed; ``kept`` is not served here (what is
        pushed may be dropped like the rest)."""
        data = message.encode() if isinstance(message, str) else message
        self.put((wire.frame_header(wire.TEXT if isinstance(message, str) else wire.BINARY, len(data)), data))

    def put(self, parts: tuple[bytes, ...]) -> None:
        """A WebSocket frame, as parts to be joined."""
        size = sum(map(len, parts))
        self.backlog.append((size, parts))
        self.size += size
        while len(self.backlog) > CLIENT_BACKLOG or (self.size > CLIENT_BACKLOG_BYTES and len(self.backlog) > 1):
            self.size -= self.backlog.popleft()[0]
            self.on_drop()
        self.waiting.set()

    def put_frames(self, parts: list[bytes], per: int) -> None:
        """Whole frames of ``per`` parts each, in order: written at once when nothing waits
        before them and the socket takes them (one write, no wake-up of the sender), else each
        into the backlog, as ``put``. On the server's loop."""
        transport = self.transport
        if (not self.backlog and not self.protocol.writing_paused and transport is not None
                and not transport.is_closing() and not self.ws.closed and sum(map(len, parts)) <= WRITE_BYTES):
            self.on_write()  # (counted first: a client may read what is written before the count)
            transport.write(b"".join(parts))
            return
        for i in range(0, len(parts), per):
            self.put(tuple(parts[i:i + per]))

    async def send_all(self) -> None:
        backlog, transport = self.backlog, self.transport
        while not self.ws.closed:
            await self.waiting.wait()
            self.waiting.clear()
            while backlog and not self.ws.closed:
                size, parts = backlog.popleft()
                batch = list(parts)
                while backlog and size < WRITE_BYTES:
                    more, parts = backlog.popleft()
                    batch.extend(parts)
                    size += more
                self.size -= size
                if transport is None or transport.is_closing():
                    return  # the client went away; its handler ends the connection
                self.on_write()  # (counted first: a client may read what is written before this line runs)
                transport.write(b"".join(batch))  # (whole frames: aiohttp's own, a ping, go between them)
                if self.protocol.writing_paused:
                    try:
                        await self.protocol._drain_helper()  # (as aiohttp's own writer waits)
                    except ConnectionError:
                        return


class Handoff:
    """Frames handed from Zenoh's callback threads to a web server's loop, served there in
    batches by ``serve(items)`` (issue 35): the loop wakes for what a client is sent anyway,
    and a callback thread that did the work (decoding, JSON, OSC) fought the loop for the
    GIL. ``put`` is a ``Streams`` ``direct``: it wakes the loop only when nothing waits, and
    says False (the sample then goes to the node's own queue and worker, bounded and
    counted there) when ``most`` samples or ``most_bytes`` wait already, or the server is
    not running: what waits here is bounded.

    ``gather_s`` (0: none): once the loop has served a batch it comes round again by itself
    after ``gather_s`` and serves what came meanwhile, without being asked (no wake-up from
    the callback thread, and a robot's frame and the derived frame made of it go to a client
    in one write: half the loop's wake-ups and writes with one robot at 50 Hz), until it
    comes round to nothing; a sample then waits ``gather_s`` at most."""

    def __init__(self, web: WebServer, serve: Callable[[list[tuple[str, Any]]], None], most: int = 64,
                 most_bytes: int = 4 << 20, gather_s: float = 0.0) -> None:
        self.web, self.serve, self.most, self.most_bytes, self.gather_s = web, serve, most, most_bytes, gather_s
        self._items: deque[tuple[str, Any]] = deque()
        self._bytes = 0
        self._lock = Lock()
        self._armed = False  # the loop comes round by itself (gather_s): nobody needs to ask it (under _lock)

    def put(self, key: str, payload: Any) -> bool:
        size = item_size((key, payload))
        with self._lock:
            if len(self._items) >= self.most or (self._items and self._bytes + size > self.most_bytes):
                return False
            self._items.append((key, payload))
            self._bytes += size
            if len(self._items) > 1 or self._armed or self.web.call(self._run):
                return True
            self._items.pop()
            self._bytes -= size
            return False

    def _run(self) -> None:  # (on the loop)
        with self._lock:
            items = list(self._items)
            self._items.clear()
            self._bytes = 0
            again = self._armed = bool(items) and self.gather_s > 0
        if again:  # (by itself while samples come; a round that finds none ends it)
            asyncio.get_running_loop().call_later(self.gather_s, self._run)
        if items:
            self.serve(items)
