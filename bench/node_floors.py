"""The floors of three of the show's sinks (issue 35): minimal harnesses that do a node's
essential work with the same libraries and no sonibus, fed the same frames as
``show.py``'s other floors (one robot × 17 joints at its rate, msgpack, zenoh-python).

- **foxglove**: what the show's Foxglove client receives from the node, made the same way
  (``json``, compact, the channels' JSON byte for byte in shape) and sent as the node sends
  it: subscribers of the frames and of the derived frames (fed both, as the node is in the
  show); each frame gives 19 messages — each joint's sample ``{"t", "seq", "v"}`` on its own
  channel (17), the frame whole, and its arms' 12 transforms as ``foxglove.FrameTransforms``
  (quaternions of Pepper's arm chains, numbers written here) — and each derived frame 26, a
  value each; every message is a binary WebSocket frame with Foxglove's 13-byte header
  (opcode 1, subscription id, log time), and what one bus message gives goes to the one
  client connected (a reader in a process of its own) in ONE transport write (the fewest the
  protocol allows: a WebSocket message per Foxglove message), on an aiohttp server's loop.
  No advertising, subscribing, latching, limits or info channels (once, not per frame);
- **recorder**: a subscriber that decodes each frame, makes it JSON and adds it to an
  MCAP file (``mcap``'s ``Writer``, zstd chunks of 1 MiB, as the recorder's);
- **oscquery**: subscribers of the frames and of the derived frames (fed both, as the node
  is in the show: its namespace serves derived values too) that keep each one's payload as
  the latest of its key (what answering a question needs), and send each of a frame's values
  as an OSC message (address bytes made once, ``struct.pack``), one binary WebSocket message
  each (aiohttp), to the one client connected: the show's OSCQuery client LISTENs to every
  joint, to no derived value.

The nodes do more than their floors (the features node's derived frames and the robot's
events come in too, Foxglove's views and per-joint channels go out, the recorder writes
each frame's transforms beside it, and each derived frame): the ratio says what that and
sonibus's own work cost. (Before issue 35 the recorder wrote a frame's joints a message each.)

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
FED_DERIVED = ("foxglove", "oscquery")  # floors fed a derived frame beside each frame (floor.DERIVED), as nodes
# Pepper's arm chains (robots.json's, from its URDF): joint (the frame's J5..J16), parent, origin, origin's
# rotation (quaternion), axis (None: the hand, a point)
_BENT = (0.0, -0.07845878036326605, 0.0, 0.9969173585528084)
_NONE = (0.0, 0.0, 0.0, 1.0)
ARMS = [(f"{side}{joint}", f"{side}{parent}" if parent else "Torso", (x, y * (1 if side == "L" else -1), z), rpy, axis)
        for side in "LR" for joint, parent, (x, y, z), rpy, axis in (
            ("ShoulderPitch", "", (-0.057, 0.14974, 0.08682), _NONE, (0.0, 1.0, 0.0)),
            ("ShoulderRoll", "ShoulderPitch", (0.0, 0.0, 0.0), _NONE, (0.0, 0.0, 1.0)),
            ("ElbowYaw", "ShoulderRoll", (0.1812, 0.015, 0.00013), _BENT, (1.0, 0.0, 0.0)),
            ("ElbowRoll", "ElbowYaw", (0.0, 0.0, 0.0), _NONE, (0.0, 0.0, 1.0)),
            ("WristYaw", "ElbowRoll", (0.15, 0.0, 0.0), _NONE, (1.0, 0.0, 0.0)),
            ("Hand", "WristYaw", (0.025, 0.0, 0.0), _NONE, None))]


def websocket_floor(endpoint: str, port: int, ready: Any, done: Any,
                    take: Callable[[dict[Any, Any], str, bytes], Awaitable[None]],
                    keys: tuple[str, ...] = ("*/frame",)) -> None:
    """Samples of ``keys`` from a session listening on ``endpoint``, each handed to
    ``take(clients, key, payload)`` on the loop of an aiohttp WebSocket server on ``port``
    (``clients``: each connected client's WebSocketResponse → its transport)."""
    import zenoh
    from aiohttp import web

    async def main() -> None:
        loop = asyncio.get_running_loop()
        clients: dict[web.WebSocketResponse, Any] = {}

        async def websocket(request: web.Request) -> web.WebSocketResponse:
            ws = web.WebSocketResponse(compress=False)
            await ws.prepare(request)
            clients[ws] = request.transport
            async for _ in ws:
                pass
            clients.pop(ws, None)
            return ws

        app = web.Application()
        app.router.add_get("/", websocket)
        runner = web.AppRunner(app)
        await runner.setup()
        await web.TCPSite(runner, "127.0.0.1", port).start()
        session = zenoh.open(zenoh_config(listen=endpoint))
        subscribers = [session.declare_subscriber(key, lambda sample: asyncio.run_coroutine_threadsafe(
            take(clients, str(sample.key_expr), sample.payload.to_bytes()), loop)) for key in keys]
        ready.set()
        await asyncio.to_thread(done.wait)
        for subscriber in subscribers:
            subscriber.undeclare()
        session.close()
        await runner.cleanup()

    asyncio.run(main())


def foxglove_floor(endpoint: str, port: int, ready: Any, done: Any) -> None:
    """What the show's Foxglove client gets of each frame and derived frame (the module's
    docstring), each bus message's Foxglove messages in one write to the client on ``port``."""
    import math

    import msgpack

    encode = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode
    ids: dict[str, int] = {}  # channel → subscription id (the client's subscription of it)
    pack = HEADER.pack

    def message(topic: str, data: dict[str, Any], log_ns: int) -> bytes:
        body = encode(data).encode()
        size = HEADER.size + len(body)
        head = bytes((0x82, size)) if size < 126 else b"\x82\x7e" + size.to_bytes(2, "big") if size < 1 << 16 \
            else b"\x82\x7f" + size.to_bytes(8, "big")
        return head + pack(1, ids.get(topic) or ids.setdefault(topic, len(ids) + 1), log_ns) + body

    def transforms(robot: str, frame: dict[str, Any]) -> dict[str, Any]:
        sec = math.floor(frame["t"])
        stamp = {"sec": sec, "nsec": round((frame["t"] - sec) * 1e9)}
        out = []
        for (joint, parent, (x, y, z), (ax, ay, az, aw), axis), angle in zip(ARMS, frame["v"][5:], strict=True):
            if axis is not None:  # (the origin's rotation, then the joint's about its axis)
                s, c = math.sin(angle / 2), math.cos(angle / 2)
                bx, by, bz, bw = axis[0] * s, axis[1] * s, axis[2] * s, c
                ax, ay, az, aw = (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                                  aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)
            out.append({"timestamp": stamp, "parent_frame_id": f"{robot}/{parent}",
                        "child_frame_id": f"{robot}/{joint}", "translation": {"x": x, "y": y, "z": z},
                        "rotation": {"x": ax, "y": ay, "z": az, "w": aw}})
        return {"transforms": out}

    async def send(clients: dict[Any, Any], key: str, payload: bytes) -> None:
        robot, _, section = key.partition("/")
        frame, log_ns = msgpack.unpackb(payload), time.time_ns()
        t, seq = frame["t"], frame["seq"]
        folder = f"{robot}/joints/" if section == "frame" else f"{robot}/derived/"
        out = [message(folder + name, {"t": t, "seq": seq, "v": v}, log_ns)
               for name, v in zip(frame["names"], frame["v"], strict=True)]
        if section == "frame":
            out += [message(f"{robot}/frame", frame, log_ns), message(f"{robot}/tf", transforms(robot, frame), log_ns)]
        data = b"".join(out)
        for transport in list(clients.values()):
            transport.write(data)

    websocket_floor(endpoint, port, ready, done, send, ("*/frame", "*/derived"))


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
    """Each frame as JSON, one MCAP message, into a file with zstd chunks (the writer on a thread
    of its own, as the recorder's, fed by a queue)."""
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
               ready, done)
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

    async def send(clients: dict[Any, Any], key: str, payload: bytes) -> None:
        latest[key] = payload
        if key.endswith("/derived"):  # (kept: no client listens to a derived value)
            return
        robot, frame = key.partition("/")[0], msgpack.unpackb(payload)
        for name, value in zip(frame["names"], frame["v"], strict=True):
            prefix = addresses.get((robot, name)) or addresses.setdefault((robot, name), address(robot, name))
            data = prefix + struct.pack(">f", value)
            for ws in list(clients):
                await ws.send_bytes(data)

    websocket_floor(endpoint, port, ready, done, send, ("*/frame", "*/derived"))


def subscribed(endpoint: str, each: Any, ready: Any, done: Any) -> None:
    """``each(sample)`` for every frame, on a session listening on ``endpoint``, until ``done``."""
    import zenoh
    session = zenoh.open(zenoh_config(listen=endpoint))
    subscriber = session.declare_subscriber("*/frame", each)
    ready.set()
    done.wait()
    subscriber.undeclare()
    session.close()


def measure(seconds: float, warmup_s: float = 3.0, nodes: tuple[str, ...] = NODES) -> dict[str, float]:
    """CPU % of one core of each floor (of ``nodes``) over ``seconds`` after ``warmup_s``, each
    fed its own publisher of one robot × 17 joints at ``RATE_HZ``."""
    if not nodes:
        return {}
    done = CONTEXT.Event()
    endpoints = {name: f"tcp/127.0.0.1:{free_port()}" for name in nodes}
    web_ports = {name: free_port() for name in ("foxglove", "oscquery") if name in nodes}  # (each with a client)
    readies = {name: CONTEXT.Event() for name in (*endpoints, *(f"{name} client" for name in web_ports))}
    with tempfile.TemporaryDirectory() as folder:
        targets = {"foxglove": (foxglove_floor, web_ports.get("foxglove")), "recorder": (recorder_floor, folder),
                   "oscquery": (oscquery_floor, web_ports.get("oscquery"))}
        floors = {name: CONTEXT.Process(target=target, args=(endpoints[name], where, readies[name], done),
                                        daemon=True) for name, (target, where) in targets.items() if name in nodes}
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
                                                                     fed, out), daemon=True,
                                              kwargs={"rate_hz": RATE_HZ, "derived": name in FED_DERIVED}))
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
