"""Fixtures of the OSCQuery tests: a simulated robot, the OSC gateway and an OSCQuery
node on a loopback bus, each on a free port; the figures measured, printed at the end."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import aiohttp
import pytest
import requests

from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.adapters.oscquery import OscQuery, OscQueryConfig

from ..conftest import Network, wait_for
from ..net.conftest import _stale_removed, topology  # noqa: F401  (the mDNS test's namespaces)

RATE = 50  # frames/s of the simulated robots


@dataclass
class Served:
    """The running nodes, and the OSCQuery server's URL."""

    net: Network
    gateway: OscGateway
    node: OscQuery

    @property
    def url(self) -> str:
        return self.node.url

    def get(self, path: str = "/") -> requests.Response:
        return requests.get(self.url + path, timeout=5)

    def json(self, path: str = "/") -> Any:
        response = self.get(path)
        assert response.status_code == 200, (path, response.status_code, response.text)
        return json.loads(response.text)  # (json.loads refuses nothing, but NaN would show as 'NaN': checked apart)

    def wait_node(self, path: str, timeout: float = 10.0) -> dict[str, Any]:
        return wait_for(lambda: self.get(path).status_code == 200 and self.json(path), timeout, f"{path} served")


def serve(net: Network, **options: Any) -> Served:
    gateway = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0"), name="gateway"))
    port = gateway.udp_address[1]
    config = OscQueryConfig(**{"listen": "127.0.0.1:0", "gateway": f"127.0.0.1:{port}", "mdns": False, **options})
    return Served(net, gateway, net.start(OscQuery(config, name="oscquery")))


@pytest.fixture
def served(net: Network) -> Served:
    """A simulated ``pepper`` at ``RATE``, a gateway and an OSCQuery node, ``pepper`` served."""
    net.sim("pepper", rate_hz=RATE, idle=True)
    out = serve(net)
    out.wait_node("/pepper/joints/HeadYaw")
    return out


class Socket:
    """A real WebSocket client (aiohttp) run on a loop of its own: ``send`` commands,
    ``messages`` gathered as they come (binary OSC as bytes, text as str)."""

    def __init__(self, url: str) -> None:
        self.url = url.replace("http://", "ws://") + "/"
        self.messages: list[str | bytes] = []
        self.arrived: list[float] = []  # time.monotonic() of each message, as the reader took it
        self.loop = asyncio.new_event_loop()
        self.closed = False
        self._ws: aiohttp.ClientWebSocketResponse | None = None
        self._session: aiohttp.ClientSession | None = None
        self._reader: asyncio.Task[None] | None = None
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()
        self._run(self._open())

    def _run(self, coro: Any, timeout: float = 10.0) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    async def _open(self) -> None:
        self._session = aiohttp.ClientSession()
        self._ws = await self._session.ws_connect(self.url)
        self._reader = asyncio.create_task(self._read())

    async def _read(self) -> None:
        assert self._ws is not None
        async for message in self._ws:
            if message.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY):
                self.arrived.append(time.monotonic())
                self.messages.append(message.data)
        self.closed = True

    def send(self, data: str | bytes | dict[str, Any]) -> None:
        async def send() -> None:
            assert self._ws is not None
            if isinstance(data, bytes):
                await self._ws.send_bytes(data)
            else:
                await self._ws.send_str(data if isinstance(data, str) else json.dumps(data))
        self._run(send())

    def texts(self) -> list[dict[str, Any]]:
        return [json.loads(m) for m in list(self.messages) if isinstance(m, str)]

    def close(self) -> None:
        if self.loop.is_closed():
            return

        async def close() -> None:
            if self._ws is not None:
                await self._ws.close()
            if self._session is not None:
                await self._session.close()
        try:
            self._run(close())
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(5)
            self.loop.close()


def opener(make: Callable[[str], Socket]) -> Iterator[Callable[[str], Socket]]:
    """``open_(url)`` makes a client with ``make``; every one is closed when the test ends."""
    opened: list[Socket] = []

    def open_(url: str) -> Socket:
        opened.append(make(url))
        return opened[-1]

    try:
        yield open_
    finally:
        for socket in opened:
            socket.close()


@pytest.fixture
def websocket() -> Iterator[Callable[[str], Socket]]:
    """``websocket(url)`` opens a client, closed at the end of the test."""
    yield from opener(Socket)


@contextlib.contextmanager
def stalled(url: str, paths: list[str]) -> Iterator[socket.socket]:
    """A WebSocket client that LISTENs to ``paths`` and never reads its socket (a small
    receive buffer: the server's sends block once the kernel's buffers are full)."""
    port = int(url.rsplit(":", 1)[1])
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
        sock.connect(("127.0.0.1", port))
        sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode() +
                     b"Upgrade: websocket\r\nConnection: Upgrade\r\n"
                     b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
        for path in paths:
            sock.sendall(masked(json.dumps({"COMMAND": "LISTEN", "DATA": path}).encode()))
        yield sock


def masked(payload: bytes) -> bytes:
    """A client's WebSocket text frame (RFC 6455: masked), for a payload under 126 bytes."""
    mask = b"\x01\x02\x03\x04"
    return bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
