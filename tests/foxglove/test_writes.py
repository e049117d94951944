"""How the hub writes to its clients (issue 35): what is due to a client goes in one
transport write per wake-up, several protocol messages in it, every one still its own
WebSocket message to the client, in order; and a client that stops reading holds a bounded
amount, its oldest messages dropped and counted, the node running on."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time

import aiohttp

from sonibus.adapters.foxglove import framed
from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer, _describe
from sonibus.bus.web import CLIENT_BACKLOG_BYTES

from ..conftest import wait_for
from .test_server import PROTOCOLS, connect, run

TOPIC = "pepper/joints/HeadYaw"


def _log(server: FoxgloveServer, i: int, padding: int = 0) -> None:
    assert server.hub.log(TOPIC, {"t": float(i), "seq": i, "v": 0.5, "pad": "x" * padding}, i,
                          lambda id_: _describe(id_, TOPIC))


def _started(net) -> FoxgloveServer:
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    wait_for(lambda: server.port, 5, "the server listening")
    _log(server, 0)
    return server


def test_what_is_due_to_a_client_goes_in_one_write_each_message_its_own_in_order(net):
    server = _started(net)

    async def scenario() -> list[int]:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, server.port)
            await client.until(lambda _: TOPIC in client.channels)
            await client.subscribe({1: TOPIC})
            await client.until(lambda got: len(got) == 1)  # the latest
            writes = server.stats["writes"]
            server.web.call(time.sleep, 0.5)  # the loop held: the next 200 are due at once when it runs
            for i in range(1, 201):
                _log(server, i)
            got = await client.until(lambda got: len(got) == 200)
            assert 1 <= server.stats["writes"] - writes <= 2, \
                f"{server.stats['writes'] - writes} writes for 200 messages due at once"
            return [json.loads(payload)["seq"] for _, _, payload in got]

    assert run(scenario()) == list(range(1, 201))
    assert server.stats["sent"] == 201


def _handshake(port: int) -> socket.socket:
    """A WebSocket client on a bare socket with a small receive buffer, to stop reading at will."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.settimeout(5)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                  f"Sec-WebSocket-Protocol: {PROTOCOLS[1]}\r\n\r\n").encode())
    answer = b""
    while b"\r\n\r\n" not in answer:
        answer += sock.recv(1)
    assert answer.startswith(b"HTTP/1.1 101"), answer
    return sock


def _send_text(sock: socket.socket, text: str) -> None:
    data, mask = text.encode(), os.urandom(4)
    assert len(data) < 126
    sock.sendall(struct.pack("!BB", 0x81, 0x80 | len(data)) + mask + bytes(b ^ mask[i % 4] for i, b in
                                                                             enumerate(data)))


def test_a_client_that_stops_reading_holds_a_bounded_amount_and_loses_its_oldest(net):
    server = _started(net)
    sock = _handshake(server.port)
    try:
        wait_for(lambda: server.hub.clients == 1, 5, "the client connected")
        _send_text(sock, json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 1}]}))
        wait_for(lambda: server.stats["sent"] >= 1, 5, "the latest message sent")
        for i in range(1, 1201):  # 1,200 messages of 20 kB (24 MB), never read
            _log(server, i, padding=20_000)
            if i % 100 == 0:
                wait_for(lambda i=i: server.stats["sent"] > i, 5, "messages taken by the server's loop")
        wait_for(lambda: server.stats["dropped_for_clients"] > 0, 10, "a client that does not read losing some")
        (client,) = list(server.hub._clients)

        async def held() -> tuple[int, int]:
            return client.size, client.transport.get_write_buffer_size()

        waiting, unsent = server.web.submit(held()).result(5)
        assert waiting <= CLIENT_BACKLOG_BYTES + 25_000, waiting
        assert unsent <= 2 * framed.WRITE_BYTES + (64 << 10), f"{unsent} bytes in the transport's buffer"
        assert server.state == "running"
    finally:
        sock.close()
