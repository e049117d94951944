"""The show's three servers (web pages, OSCQuery, Foxglove) as the server families see them:
raw clients that can say anything (``RawHttp``, ``RawWs``: a socket, a handshake by hand,
frames built byte by byte), and ``serving``, the check that each still serves a new
well-behaved client: a page gets its state (``hello``, the robots, a frame of pepper), an
OSCQuery ``LISTEN`` gets values, a Foxglove client subscribes and gets messages.

No pytest here: ``bench/soak.py`` runs the campaign too."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import select
import socket
import struct
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import aiohttp

if TYPE_CHECKING:
    from .checks import Report
    from .show import Show

SERVERS = ("web", "oscquery", "foxglove")
WS_PATH = {"web": "/ws", "oscquery": "/", "foxglove": "/"}
WS_PROTOCOL = {"foxglove": "foxglove.websocket.v1"}
# the show's [limits] of each server (show.py), small so that the limits are reached fast
CONNECTIONS, CLIENTS, TIMEOUT_S = 32, 8, 1.0
ANSWER_S = TIMEOUT_S + 4.0  # a server answers or closes within this, or it hangs (a problem)
SERVING_S = 10.0            # a well-behaved client is served within this
TEXT, BINARY, CLOSE, PING, PONG = 0x1, 0x2, 0x8, 0x9, 0xA


def port(show: Show, server: str) -> int:
    return int(getattr(show.ports, server))


# -- HTTP ---------------------------------------------------------------------------------

def exchange(port_: int, data: bytes, timeout: float = ANSWER_S) -> str:
    """Send ``data`` on a new connection; what came back: the status code of the first
    answer, ``closed`` (closed without one), ``reset``, or ``hung`` (neither within ``timeout``)."""
    with socket.create_connection(("127.0.0.1", port_), timeout=timeout) as sock:
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # (answered and closed before the end)
            sock.sendall(data)
        head = b""
        deadline = time.monotonic() + timeout
        try:
            while b"\r\n" not in head:
                sock.settimeout(max(0.01, deadline - time.monotonic()))
                chunk = sock.recv(4096)
                if not chunk:
                    return "closed" if not head else f"closed after {head[:20]!r}"
                head += chunk
        except TimeoutError:
            return "hung"
        except ConnectionResetError:
            return "reset"
    parts = head.split(b" ", 2)
    return parts[1].decode("latin-1") if len(parts) > 1 and head.startswith(b"HTTP/1.") else f"odd {head[:20]!r}"


def closed_within(sock: socket.socket, deadline: float) -> tuple[bool, bytes]:
    """Whether the server closes ``sock`` by ``deadline`` (looked at once at least), and the
    first bytes it said before."""
    said = b""
    try:
        while True:
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            chunk = sock.recv(65536)
            if not chunk:
                return True, said
            said = said or chunk[:32]
    except TimeoutError:
        return False, said
    except OSError:
        return True, said


def cut_within(sock: socket.socket, deadline: float) -> bool:
    """Whether the server cuts ``sock`` (a reset, or its end) by ``deadline``, without reading
    from it: a client that never reads must not start to."""
    poller = select.poll()
    poller.register(sock, select.POLLRDHUP | select.POLLHUP | select.POLLERR)
    while True:
        if poller.poll(max(10, int((deadline - time.monotonic()) * 1000))):
            return True
        if time.monotonic() >= deadline:
            return False


# -- WebSocket ------------------------------------------------------------------------------

def frame(opcode: int, payload: bytes, fin: bool = True, masked: bool = True, rsv: int = 0,
          length: int | None = None) -> bytes:
    """One WebSocket frame as a client sends it (masked), or as it must not (``masked`` False,
    ``rsv`` bits, a ``length`` that lies)."""
    size = len(payload) if length is None else length
    head = bytes([(0x80 if fin else 0) | (rsv & 0x7) << 4 | opcode & 0xF])
    mask_bit = 0x80 if masked else 0
    if size < 126:
        head += bytes([mask_bit | size])
    elif size < 1 << 16:
        head += bytes([mask_bit | 126]) + struct.pack(">H", size)
    else:
        head += bytes([mask_bit | 127]) + struct.pack(">Q", size)
    if not masked:
        return head + payload
    key = os.urandom(4)
    return head + key + bytes(b ^ key[i % 4] for i, b in enumerate(payload))


@dataclass
class Outcome:
    kind: str           # answered, closed, eof, hung
    code: int = 0       # a close frame's code
    payload: bytes = b""


class RawWs:
    """A WebSocket client made by hand on a socket: it sends any bytes (``send``) and reads
    the server's frames (``until``)."""

    def __init__(self, port_: int, server: str, rcvbuf: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf:  # (a client that never reads: the server's sends block soon)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.settimeout(ANSWER_S)
        self.sock.connect(("127.0.0.1", port_))
        key = base64.b64encode(os.urandom(16)).decode()
        protocol = f"Sec-WebSocket-Protocol: {WS_PROTOCOL[server]}\r\n" if server in WS_PROTOCOL else ""
        self.sock.sendall(f"GET {WS_PATH[server]} HTTP/1.1\r\nHost: 127.0.0.1:{port_}\r\nUpgrade: websocket\r\n"
                          f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                          f"{protocol}\r\n".encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError(f"{server}: closed during the WebSocket handshake")
            self.buf += chunk
        head, _, self.buf = self.buf.partition(b"\r\n\r\n")
        if not head.startswith(b"HTTP/1.1 101"):
            raise ConnectionError(f"{server}: handshake answered {head[:40]!r}")
        self.open = True

    def send(self, data: bytes) -> bool:
        """Send raw bytes; False if the server has closed the connection."""
        try:
            self.sock.sendall(data)
            return True
        except OSError:
            self.open = False
            return False

    def text(self, text: str) -> bool:
        return self.send(frame(TEXT, text.encode()))

    def _read(self, size: int, deadline: float) -> bytes | None:
        while len(self.buf) < size:
            self.sock.settimeout(max(0.01, deadline - time.monotonic()))
            chunk = self.sock.recv(65536)
            if not chunk:
                return None
            self.buf += chunk
        data, self.buf = self.buf[:size], self.buf[size:]
        return data

    def until(self, wanted: Any, timeout: float = ANSWER_S) -> Outcome:
        """Read frames until ``wanted(opcode, payload)`` holds (``answered``), the server closes
        (``closed`` with its code, or ``eof``), or ``timeout`` passes (``hung``)."""
        deadline = time.monotonic() + timeout
        try:
            while True:
                head = self._read(2, deadline)
                if head is None:
                    self.open = False
                    return Outcome("eof")
                size = head[1] & 0x7F
                if size >= 126:
                    extra = self._read(2 if size == 126 else 8, deadline)
                    if extra is None:
                        self.open = False
                        return Outcome("eof")
                    size = struct.unpack(">H" if len(extra) == 2 else ">Q", extra)[0]
                payload = self._read(size, deadline)
                if payload is None:
                    self.open = False
                    return Outcome("eof")
                opcode = head[0] & 0xF
                if opcode == CLOSE:
                    self.open = False
                    return Outcome("closed", struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 0)
                if wanted(opcode, payload):
                    return Outcome("answered", payload=payload)
        except TimeoutError:
            return Outcome("hung")
        except OSError:
            self.open = False
            return Outcome("eof")

    def close(self) -> None:
        self.open = False
        self.sock.close()


# -- the check: each server serves a new well-behaved client ------------------------------------

async def _web(session: aiohttp.ClientSession, port_: int) -> None:
    async with session.ws_connect(f"ws://127.0.0.1:{port_}/ws") as ws:
        seen: set[str] = set()
        while not {"hello", "robots", "frame"} <= seen:
            message = json.loads(await ws.receive_str())
            if message["type"] == "robots" and "pepper" not in message["robots"]:
                continue
            if message["type"] == "frame" and message["robot"] != "pepper":
                continue
            seen.add(message["type"])


async def _oscquery(session: aiohttp.ClientSession, port_: int) -> None:
    async with session.get(f"http://127.0.0.1:{port_}/pepper/joints/HeadYaw") as response:
        assert response.status == 200, f"GET /pepper/joints/HeadYaw answered {response.status}"
    async with session.ws_connect(f"ws://127.0.0.1:{port_}/") as ws:
        await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": "/pepper/joints/HeadYaw"}))
        while True:
            message = await ws.receive()
            if message.type == aiohttp.WSMsgType.BINARY and message.data.startswith(b"/pepper/joints/HeadYaw\0"):
                return
            assert message.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY), message


async def _foxglove(session: aiohttp.ClientSession, port_: int) -> None:
    async with session.ws_connect(f"ws://127.0.0.1:{port_}/", protocols=(WS_PROTOCOL["foxglove"],)) as ws:
        subscribed = False
        while True:
            message = await ws.receive()
            if message.type == aiohttp.WSMsgType.TEXT and not subscribed:
                data = json.loads(message.data)
                frame_channel = [c["id"] for c in data.get("channels", ()) if c["topic"] == "pepper/frame"]
                if data["op"] == "advertise" and frame_channel:
                    await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": 1, "channelId": frame_channel[0]}]}))
                    subscribed = True
            elif message.type == aiohttp.WSMsgType.BINARY and message.data[:5] == b"\x01\x01\x00\x00\x00":
                return
            else:
                assert message.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY), message


async def _each(show: Show) -> dict[str, str | float]:
    """Each server's time to serve its well-behaved client, or why it did not."""
    async def timed(name: str, probe: Any) -> str | float:
        started = time.monotonic()
        try:
            async with aiohttp.ClientSession() as session:
                await asyncio.wait_for(probe(session, port(show, name)), SERVING_S)
        except Exception as exc:  # (each failure is one problem line: what the client saw)
            return f"{type(exc).__name__}: {str(exc)[:200]}"
        return round(time.monotonic() - started, 3)
    probes = {"web": _web, "oscquery": _oscquery, "foxglove": _foxglove}
    results = await asyncio.gather(*(timed(name, probe) for name, probe in probes.items()))
    return dict(zip(probes, results, strict=True))


def serving(show: Show, report: Report, when: str) -> None:
    """Each server serves a new well-behaved client; the seconds each took in the figures."""
    if not show.alive:
        return  # (checks.alive says so)
    results = asyncio.run(_each(show))
    report.figures.setdefault("serving_s", {})[when] = results
    for name, result in results.items():
        report.check(not isinstance(result, str), f"{when}: the {name} server did not serve a well-behaved client "
                                                  f"within {SERVING_S:g} s: {result}")


def no_server_errors(report: Report) -> None:
    """No server counted an error of its own (a handler that raised: a 500, a WebSocket cut), from
    the counters the nodes logged as they stopped (``checks.stopped``)."""
    counters = report.figures.get("node_counters", {})
    for name in SERVERS:
        errors = counters.get(name, {}).get("errors", 0)
        report.check(errors == 0, f"the {name} server counted {errors} error(s) of its own (a handler that raised; "
                                  "the log says which)")
