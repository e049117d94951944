"""What a Foxglove client receives, message by message and byte by byte, for a scripted run,
against what the server sent before its writes were coalesced (issue 35:
several protocol messages in one transport write, each message encoded once for all
clients). ``data/scripted_run.json`` was recorded with the server of 0e7ba47
(``python -m tests.foxglove.test_wire_unchanged`` records it again: only to be done
for a change of what clients receive, said in docs/foxglove.md).

The script: channels made before the client connects (a joint, a frame, an event
channel with history), the client subscribes to all of them (latched and history
messages first), live messages on each, a channel made while subscribed (advertised,
then subscribed), a bad request (a status), and a robot forgotten (unadvertised). Two
clients are connected: both must get the same run (the second with its own
subscription ids), and messages of more than 125 and of more than 65,535 bytes
checks the longer WebSocket frame headers."""

from __future__ import annotations

import asyncio
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import aiohttp

from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer, _describe

from ..conftest import Network, wait_for
from .test_server import PROTOCOLS

GOLDEN = Path(__file__).parent / "data" / "scripted_run.json"
T0 = 1_700_000_000_000_000_000


def joint(i: int) -> dict[str, Any]:
    return {"t": 1.5 + i / 50, "seq": i, "v": round(0.01 * i - 0.3, 6)}


def frame(i: int) -> dict[str, Any]:
    return {"t": 1.5 + i / 50, "seq": i, "names": ["HeadYaw", "HeadPitch"], "v": [0.01 * i, -0.02 * i]}


def event(i: int, padding: int = 0) -> dict[str, Any]:
    return {"t": 1.5 + i / 50, "kind": "behavior", "name": "wave", "state": "started", "note": "x" * padding}


def log(server: FoxgloveServer, topic: str, message: dict[str, Any], n: int) -> None:
    assert server.hub.log(topic, message, T0 + n * 20_000_000, lambda id_: _describe(id_, topic),
                          history=topic.endswith("/log") or "/events/" in topic)


async def _read(ws: aiohttp.ClientWebSocketResponse, got: list[tuple[str, str]], count: int) -> None:
    deadline = time.monotonic() + 15
    while len(got) < count:
        left = deadline - time.monotonic()
        assert left > 0, f"timed out after {len(got)} of {count} messages: {got[-3:]}"
        message = await ws.receive(timeout=left)
        if message.type == aiohttp.WSMsgType.TEXT:
            data = json.loads(message.data)
            if data.get("op") == "serverInfo":  # (its session id is the server's start time)
                data["sessionId"], data["metadata"] = "S", {"sonibus": "V"}  # (and its version)
                got.append(("text", json.dumps(data)))
            else:
                got.append(("text", message.data))
        elif message.type == aiohttp.WSMsgType.BINARY:
            data = bytes(message.data)  # (its length, its hash and its start: the golden file stays small)
            got.append(("binary", f"{len(data)} {hashlib.sha256(data).hexdigest()} {data[:40].hex()}"))
        else:
            raise AssertionError(f"the server closed the connection: {message}")


async def _script(server: FoxgloveServer) -> list[list[tuple[str, str]]]:
    """Every message each of two clients received, in order."""
    for i in range(3):
        log(server, "pepper/joints/HeadYaw", joint(i), i)
        log(server, "pepper/frame", frame(i), i)
        log(server, "pepper/events/behavior", event(i), i)
    got: list[list[tuple[str, str]]] = [[], []]
    async with aiohttp.ClientSession() as session:
        clients = [await session.ws_connect(f"ws://127.0.0.1:{server.port}", protocols=PROTOCOLS) for _ in got]
        for ws, mine in zip(clients, got, strict=True):
            await _read(ws, mine, 2)  # serverInfo, advertise
        channels = {c["topic"]: c["id"] for c in json.loads(got[0][1][1])["channels"]}
        for base, ws in zip((1, 100), clients, strict=True):
            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": base + n, "channelId": channels[topic]} for n, topic in enumerate(sorted(channels))]}))
        for ws, mine in zip(clients, got, strict=True):
            await _read(ws, mine, 2 + 3)  # the latest of each (the events: the latest, told of before)
        for i in range(3, 40):
            log(server, "pepper/joints/HeadYaw", joint(i), i)
            log(server, "pepper/frame", frame(i), i)
            if i % 10 == 0:
                log(server, "pepper/events/behavior", event(i, padding=200 if i == 10 else 70_000), i)
        log(server, "pepper/joints/HeadPitch", joint(40), 40)  # a new channel: advertised
        for ws, mine in zip(clients, got, strict=True):
            await _read(ws, mine, 5 + 37 * 2 + 3 + 1)
        pitch = json.loads(got[0][-1][1])["channels"][0]["id"]
        for base, ws in zip((50, 150), clients, strict=True):
            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [{"id": base, "channelId": pitch}]}))
            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [{"id": base, "channelId": 999}]}))
        for ws, mine in zip(clients, got, strict=True):
            await _read(ws, mine, len(mine) + 2)  # the latest of HeadPitch, a status (the second subscribe)
        for i in range(41, 60):
            log(server, "pepper/joints/HeadPitch", joint(i), i)
            log(server, "pepper/frame", frame(i), i)
        assert server.hub.forget("pepper/") == 4
        for ws, mine in zip(clients, got, strict=True):
            await _read(ws, mine, len(mine) + 19 * 2 + 1)  # and the unadvertise
            await ws.close()
    return got


def scripted_run() -> list[list[tuple[str, str]]]:
    network = Network()
    try:
        server = network.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
        wait_for(lambda: server.port, 5, "the server listening")
        return asyncio.run(asyncio.wait_for(_script(server), 60))
    finally:
        network.close()


def test_a_client_receives_the_same_messages_byte_for_byte_as_before():
    got = scripted_run()
    golden = [[tuple(m) for m in client] for client in json.loads(GOLDEN.read_text())]
    for number, (mine, before) in enumerate(zip(got, golden, strict=True)):
        assert len(mine) == len(before), f"client {number}: {len(mine)} messages, {len(before)} before"
        for index, (now, then) in enumerate(zip(mine, before, strict=True)):
            assert now == then, f"client {number}, message {index}: {now[1][:160]} where it was {then[1][:160]}"


if __name__ == "__main__" and "--record" in sys.argv:
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(scripted_run()))
