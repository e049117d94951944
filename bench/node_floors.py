"""The floors of three of the show's sinks (issue 35): minimal harnesses that do a node's
essential work with the same libraries and no sonibus, fed the same frames as
``show.py``'s other floors (one robot × 17 joints at its rate, msgpack, zenoh-python).

- **foxglove**: a subscriber that decodes each frame, makes it JSON and sends it, behind
  Foxglove's 13-byte message header, as one binary WebSocket message (aiohttp, the
  node's library) to the one client connected (a reader in a process of its own);
- **recorder**: a subscriber that decodes each frame and each derived frame (its
  publisher puts one of ``floor.DERIVED``'s shape beside each frame: the show's recorder
  records the features node's too), makes it JSON and adds it to an MCAP file
  (``mcap``'s ``Writer``, zstd chunks of 1 MiB, as the recorder's);
- **oscquery**: a subscriber that keeps each frame's payload as the latest (what
  answering a question needs) and sends each of its values as an OSC message (address
  bytes made once, ``struct.pack``), one binary WebSocket message each (aiohttp), to the
  one client connected: the show's OSCQuery client LISTENs to every joint.

The nodes do more than their floors (the features node's derived frames and the robot's
events come in too, Foxglove's views and per-joint channels go out, the recorder writes
each frame's transforms beside it): the ratio says what that and sonibus's own work
cost. (Before issue 35 the recorder wrote a frame's joints a message each.)

    from node_floors import measure
    measure(8.0, warmup_s=3.0)  # {"foxglove": CPU %, "recorder": ..., "oscquery": ...}
"""

from __future__ import annotations

import asyncio
import json
import os
import struct
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

from common import free_port, zenoh_config
from floor import CONTEXT, Case, cpu_ns, publish

RATE_HZ = 50
NODES = ("foxglove", "recorder", "oscquery")  # the nodes with a floor here
HEADER = struct.Struct("<BIQ")  # Foxglove's message data: opcode 1, subscription id, log time (ns)


def websocket_floor(endpoint: str, port: int, ready: Any, done: Any,
                    take: Callable[[set[Any], str, bytes], Awaitable[None]]) -> None:
    """Frames from a session listening on ``endpoint``, each handed to ``take(clients, key,
    payload)`` on the loop of an aiohttp WebSocket server on ``port`` (its clients connected)."""
    import zenoh
    from aiohttp import web

    async def main() -> None:
        loop = asyncio.get_running_loop()
        clients: set[web.WebSocketResponse] = set()

        async def websocket(request: web.Request) -> web.WebSocketResponse:
            ws = web.WebSocketResponse(compress=False)
            await ws.prepare(request)
            clients.add(ws)
            async for _ in ws:
                pass
            clients.discard(ws)
            return ws

        app = web.Application()
        app.router.add_get("/", websocket)
        runner = web.AppRunner(app)
        await runner.setup()
        await web.TCPSite(runner, "127.0.0.1", port).start()
        session = zenoh.open(zenoh_config(listen=endpoint))
        subscriber = session.declare_subscriber("*/frame", lambda sample: asyncio.run_coroutine_threadsafe(
            take(clients, str(sample.key_expr), sample.payload.to_bytes()), loop))
        ready.set()
        await asyncio.to_thread(done.wait)
        subscriber.undeclare()
        session.close()
        await runner.cleanup()

    asyncio.run(main())


def foxglove_floor(endpoint: str, port: int, ready: Any, done: Any) -> None:
    """Each frame as JSON in one binary WebSocket message to the client connected on ``port``."""
    import msgpack

    async def send(clients: set[Any], key: str, payload: bytes) -> None:
        frame = msgpack.unpackb(payload)
        data = HEADER.pack(1, 1, time.time_ns()) + json.dumps(frame).encode()
        for ws in list(clients):
            await ws.send_bytes(data)

    websocket_floor(endpoint, port, ready, done, send)


def reader(port: int, ready: Any, done: Any) -> None:
    """A floor's client (Foxglove's, OSCQuery's): connects and reads all it is sent (not measured)."""
    import aiohttp

    async def main() -> None:
        async with aiohttp.ClientSession() as session:
            deadline = time.monotonic() + 30
            while True:
                try:
                    ws = await session.ws_connect(f"ws://127.0.0.1:{port}/")
                    break
                except aiohttp.ClientError:
                    if time.monotonic() > deadline:
                        raise
                    await asyncio.sleep(0.1)
            ready.set()

            async def read() -> None:
                async for _ in ws:
                    pass
            task = asyncio.create_task(read())
            await asyncio.to_thread(done.wait)
            await ws.close()
            task.cancel()

    asyncio.run(main())


def recorder_floor(endpoint: str, folder: str, ready: Any, done: Any) -> None:
    """Each frame and each derived frame as JSON, one MCAP message each, into a file with zstd
    chunks (the writer on a thread of its own, as the recorder's, fed by a queue)."""
    import queue

    import msgpack
    from mcap.writer import CompressionType, Writer

    waiting: queue.SimpleQueue[tuple[str, bytes, int] | None] = queue.SimpleQueue()

    def write() -> None:
        with open(os.path.join(folder, "floor.mcap"), "wb") as out:
            writer = Writer(out, chunk_size=1 << 20, compression=CompressionType.ZSTD)
            writer.start()
            channels: dict[str, int] = {}
            sequence = 0
            while True:
                item = waiting.get()
                if item is None:
                    break
                key, payload, log_ns = item
                if key not in channels:
                    channels[key] = writer.register_channel(key, "json", 0)
                frame = msgpack.unpackb(payload)
                writer.add_message(channels[key], log_time=log_ns, data=json.dumps(frame).encode(),
                                   publish_time=int(frame["t"] * 1e9), sequence=sequence)
                sequence += 1
            writer.finish()

    thread = threading.Thread(target=write)
    thread.start()
    subscribed(endpoint, lambda sample: waiting.put((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns())),
               ready, done, ("*/frame", "*/derived"))
    waiting.put(None)
    thread.join()


def oscquery_floor(endpoint: str, port: int, ready: Any, done: Any) -> None:
    """Each frame's payload kept as the latest of its key, and each of its values as an OSC
    message in a binary WebSocket message to the client connected on ``port``."""
    import msgpack

    latest: dict[str, bytes] = {}
    addresses: dict[tuple[str, str], bytes] = {}

    def address(robot: str, name: str) -> bytes:
        text = f"/{robot}/joints/{name}".encode() + b"\0"
        return text + b"\0" * (-len(text) % 4) + b",f\0\0"

    async def send(clients: set[Any], key: str, payload: bytes) -> None:
        latest[key] = payload
        robot, frame = key.partition("/")[0], msgpack.unpackb(payload)
        for name, value in zip(frame["names"], frame["v"], strict=True):
            prefix = addresses.get((robot, name)) or addresses.setdefault((robot, name), address(robot, name))
            data = prefix + struct.pack(">f", value)
            for ws in list(clients):
                await ws.send_bytes(data)

    websocket_floor(endpoint, port, ready, done, send)


def subscribed(endpoint: str, each: Any, ready: Any, done: Any, keys: tuple[str, ...] = ("*/frame",)) -> None:
    """``each(sample)`` for every sample of ``keys`` (frames), on a session listening on
    ``endpoint``, until ``done``."""
    import zenoh
    session = zenoh.open(zenoh_config(listen=endpoint))
    subscribers = [session.declare_subscriber(key, each) for key in keys]
    ready.set()
    done.wait()
    for subscriber in subscribers:
        subscriber.undeclare()
    session.close()


def measure(seconds: float, warmup_s: float = 3.0) -> dict[str, float]:
    """CPU % of one core of each floor over ``seconds`` after ``warmup_s``, each fed its own
    publisher of one robot × 17 joints at ``RATE_HZ`` (the recorder's, a derived frame beside each)."""
    done = CONTEXT.Event()
    endpoints = {name: f"tcp/127.0.0.1:{free_port()}" for name in NODES}
    web_ports = {name: free_port() for name in ("foxglove", "oscquery")}  # (each with a client reading)
    readies = {name: CONTEXT.Event() for name in (*endpoints, *(f"{name} client" for name in web_ports))}
    with tempfile.TemporaryDirectory() as folder:
        floors = {
            "foxglove": CONTEXT.Process(target=foxglove_floor, args=(endpoints["foxglove"], web_ports["foxglove"],
                                                                     readies["foxglove"], done), daemon=True),
            "recorder": CONTEXT.Process(target=recorder_floor, args=(endpoints["recorder"], folder,
                                                                     readies["recorder"], done), daemon=True),
            "oscquery": CONTEXT.Process(target=oscquery_floor, args=(endpoints["oscquery"], web_ports["oscquery"],
                                                                     readies["oscquery"], done), daemon=True),
        }
        others: list[Any] = []
        try:
            for process in floors.values():
                process.start()
            if not all(readies[name].wait(30) for name in floors):
                raise RuntimeError("the node floors did not start")
            for name, port in web_ports.items():
                others.append(CONTEXT.Process(target=reader, args=(port, readies[f"{name} client"], done),
                                              daemon=True))
                others[-1].start()
            if not all(readies[f"{name} client"].wait(30) for name in web_ports):
                raise RuntimeError("the node floors' clients did not connect")
            handles = []  # (kept until the end: a queue collected here is gone for the child too)
            for name, endpoint in endpoints.items():
                fed, out = CONTEXT.Event(), CONTEXT.Queue()
                others.append(CONTEXT.Process(target=publish, args=(endpoint, Case(1, 17), seconds + warmup_s + 1,
                                                                     fed, out),
                                              kwargs={"rate_hz": RATE_HZ, "derived": name == "recorder"},
                                              daemon=True))
                others[-1].start()
                handles.append((fed, out))
            if not all(fed.wait(30) for fed, _ in handles):
                raise RuntimeError("the node floors' publishers did not find their subscribers")
            time.sleep(warmup_s)
            before, started = {name: cpu_ns(p.pid) for name, p in floors.items()}, time.monotonic()
            time.sleep(seconds)
            wall = time.monotonic() - started
            return {name: 100.0 * (cpu_ns(p.pid) - before[name]) / 1e9 / wall for name, p in floors.items()}
        finally:
            done.set()
            for process in (*others, *floors.values()):
                process.join(10)
                if process.is_alive():
                    process.kill()


if __name__ == "__main__":
    print(json.dumps(measure(4.0, 2.0), indent=1))
