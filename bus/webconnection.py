"""A connection of ``bus/web.py``'s server: aiohttp's handler telling when its timeouts close it
and cutting a client that reads nothing (``TimedHandler``), or, past the server's cap, a 503
and closed (``Refused``)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from aiohttp.web_protocol import RequestHandler


class TimedHandler(RequestHandler):
    """aiohttp's connection handler (what ``web_server.Server()`` makes), telling ``on_timeout``
    when its keep-alive timeout (here the header timeout too) closes it, with how many requests
    it had taken; and cutting the connection when what it writes makes no progress for
    ``stall_s`` (a client that never reads: aiohttp would wait to write for ever), told to
    ``on_stall``."""

    __slots__ = ("_stall", "on_stall", "on_timeout", "stall_s")

    def __init__(self, manager: Any, on_timeout: Callable[[int], None], on_stall: Callable[[], None],
                 stall_s: float, **kwargs: Any) -> None:
        super().__init__(manager, **kwargs)
        self.on_timeout, self.on_stall, self.stall_s = on_timeout, on_stall, stall_s
        self._stall: asyncio.TimerHandle | None = None

    def pause_writing(self) -> None:  # (the transport's buffer is full: the client reads nothing)
        super().pause_writing()
        if self._stall is None:
            self._stall = self._loop.call_later(self.stall_s, self._stalled)

    def resume_writing(self) -> None:
        super().resume_writing()
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None

    def _stalled(self) -> None:
        self._stall = None
        if self.transport is not None:
            self.on_stall()
            self.transport.abort()  # (close() would wait for the buffer to be read: never)

    def connection_lost(self, exc: BaseException | None) -> None:
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None
        super().connection_lost(exc)

    def _process_keepalive(self) -> None:  # (aiohttp's timer: it closes the connection if it is idle)
        was_open = not self._force_close
        super()._process_keepalive()
        if was_open and self._force_close:
            self.on_timeout(self._request_count)


class Refused(asyncio.Protocol):
    """A connection past the cap: told so, then closed."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        text = b"503: too many connections to this server at once; try again\n"
        assert isinstance(transport, asyncio.WriteTransport)
        transport.write(b"HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\nContent-Type: text/plain\r\n"
                        b"Content-Length: %d\r\n\r\n%s" % (len(text), text))
        transport.close()  # (after the write is flushed; what the client sends is ignored)
