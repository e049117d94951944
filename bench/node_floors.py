"""The floors of six of the show's sinks (issue 35): minimal harnesses that do a node's
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
- **recorder**: a subscriber that decodes each frame and each derived frame (its
  publisher puts one of ``floor.DERIVED``'s shape beside each frame: the show's recorder
  records the features node's too), makes it JSON and adds it to an MCAP file
  (``mcap``'s ``Writer``, zstd chunks of 1 MiB, as the recorder's), and each frame's arm
  transforms beside it, as the recorder writes them by default (``foxglove = true``);
- **oscquery**: subscribers of the frames and of the derived frames (fed both, as the node
  is in the show: its namespace serves derived values too) that keep each one's payload as
  the latest of its key (what answering a question needs), and send each of a frame's values
  as an OSC message (address bytes made once, ``struct.pack``), one binary WebSocket message
  each (aiohttp), to the one client connected: the show's OSCQuery client LISTENs to every
  joint, to no derived value;
- **web**, **midi**, **features**: the web node's frames at the page's rate, the MIDI
  sink's control changes on JACK, the features node's derived frames (their docstrings
  below, each with what the node does beyond it).

The nodes do more than their floors (the robot's events and info come in too, channels
are advertised and subscribed, limits kept): the ratio says what that and sonibus's own
work cost. (Before issue 35 the recorder wrote a frame's joints a message each; until
29 Nov its floor wrote no transforms, which the node writes beside each frame.)

    from node_floors import measure
    measure(8.0, warmup_s=3.0)  # {"foxglove": CPU %, "recorder": ..., "oscquery": ...}
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import struct
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from typing import Any

from common import free_port, zenoh_config
from floor import CONTEXT, Case, cpu_ns, publish
from links import Links

RATE_HZ = 50
NODES = ("foxglove", "recorder", "oscquery", "web", "midi", "features")  # the nodes with a floor here
HEADER = struct.Struct("<BIQ")  # Foxglove's message data: opcode 1, subscription id, log time (ns)
FED_DERIVED = ("foxglove", "oscquery", "recorder")  # fed a derived frame beside each frame (floor.DERIVED)
DERIVED_TAKERS = 5  # the show's sinks of derived frames (OSC, recorder, web, OSCQuery, Foxglove): the features
# node's put goes to each, its essential work as the sim's to its frames' takers (show.FRAME_TAKERS)
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


def arm_transforms(robot: str, frame: dict[str, Any]) -> dict[str, Any]:
    """A frame's arms as ``foxglove.FrameTransforms`` (what the Foxglove node sends and the
    recorder writes beside each frame: Pepper's 12 arm transforms, computed here)."""
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


def websocket_floor(endpoint: str, port: int, ready: Any, done: Any,
                    take: Callable[[dict[Any, Any], str, bytes], Awaitable[None]] | None,
                    keys: tuple[str, ...] = ("*/frame",),
                    arrive: Callable[[Any], None] | None = None,
                    pace: Callable[[dict[Any, Any]], Awaitable[None]] | None = None) -> None:
    """Samples of ``keys`` from a session listening on ``endpoint``, each handed to
    ``take(clients, key, payload)`` on the loop of an aiohttp WebSocket server on ``port``
    (``clients``: each connected client's WebSocketResponse → its transport); or to
    ``arrive(sample)`` where they arrive (Zenoh's callback thread), with ``pace(clients)``
    running on the loop meanwhile."""
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
        subscribers = [session.declare_subscriber(key, arrive or (
            lambda sample: asyncio.run_coroutine_threadsafe(take(clients, str(sample.key_expr),  # type: ignore[misc]
                                                                 sample.payload.to_bytes()), loop))) for key in keys]
        paced = asyncio.create_task(pace(clients)) if pace is not None else None
        ready.set()
        await asyncio.to_thread(done.wait)
        if paced is not None:
            paced.cancel()
        for subscriber in subscribers:
            subscriber.undeclare()
        session.close()
        await runner.cleanup()

    asyncio.run(main())


def foxglove_floor(endpoint: str, port: int, ready: Any, done: Any) -> None:
    """What the show's Foxglove client gets of each frame and derived frame (the module's
    docstring), each bus message's Foxglove messages in one write to the client on ``port``."""
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

    async def send(clients: dict[Any, Any], key: str, payload: bytes) -> None:
        robot, _, section = key.partition("/")
        frame, log_ns = msgpack.unpackb(payload), time.time_ns()
        t, seq = frame["t"], frame["seq"]
        folder = f"{robot}/joints/" if section == "frame" else f"{robot}/derived/"
        out = [message(folder + name, {"t": t, "seq": seq, "v": v}, log_ns)
               for name, v in zip(frame["names"], frame["v"], strict=True)]
        if section == "frame":
            out += [message(f"{robot}/frame", frame, log_ns),
                    message(f"{robot}/tf", arm_transforms(robot, frame), log_ns)]
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
    """Each frame and each derived frame as JSON, one MCAP message each, and each frame's arm
    transforms (``arm_transforms``: the recorder writes them beside each frame for Foxglove's
    3D panel, ``foxglove = true`` by default), into a file with zstd chunks (the writer on a
    thread of its own, as the recorder's, fed by a queue)."""
    import queue

    import msgpack
    from mcap.writer import CompressionType, Writer

    waiting: queue.SimpleQueue[tuple[str, bytes, int] | None] = queue.SimpleQueue()
    encode = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode  # (the node's)

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
                frame = msgpack.unpackb(payload)
                robot, _, section = key.partition("/")
                for topic, message in ((key, frame), *([(f"{robot}/tf", arm_transforms(robot, frame))]
                                                       if section == "frame" else [])):
                    if topic not in channels:
                        channels[topic] = writer.register_channel(topic, "json", 0)
                    writer.add_message(channels[topic], log_time=log_ns, data=encode(message).encode(),
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


def web_floor(endpoint: str, port: int, ready: Any, done: Any, update_hz: float = 25.0) -> None:
    """Each frame decoded (msgpack) and kept as its robot's latest, on Zenoh's callback thread;
    every ``1 / update_hz`` s the latest frame of each robot that sent one since, as the web
    node's ``frame`` message (JSON text), to the page connected on ``port`` (aiohttp).

    The node beyond it: each frame checked by the gate and counted, the robot's events (to the
    page, and followed for its summary line), every node's stats (checked against their schema,
    sent to the pages once a second), each robot's info asked every second, the maps panel
    asked 5 times a second (``map_values`` to the page each time), the kiosk, its commands."""
    import msgpack

    latest: dict[str, dict[str, Any]] = {}
    lock = threading.Lock()

    def keep(sample: Any) -> None:
        frame = msgpack.unpackb(sample.payload.to_bytes())
        with lock:
            latest[str(sample.key_expr).partition("/")[0]] = frame

    async def push(clients: dict[Any, Any]) -> None:
        period, due = 1.0 / update_hz, time.monotonic()
        while True:
            due += period
            await asyncio.sleep(max(0.0, due - time.monotonic()))
            with lock:
                frames = latest.copy()
                latest.clear()
            for robot, frame in frames.items():
                text = json.dumps({"type": "frame", "robot": robot, "t": frame["t"], "seq": frame["seq"],
                                   "names": frame["names"], "v": frame["v"]}, allow_nan=False)
                for ws in list(clients):
                    await ws.send_str(text)

    websocket_floor(endpoint, port, ready, done, None, arrive=keep, pace=push)


MIDI_RANGE = (-8.0, 8.0)  # the floor's joints' range, mapped onto 0..127: a few messages a joint a second


def midi_floor(endpoint: str, ready: Any, done: Any) -> None:
    """Each frame decoded (msgpack) on Zenoh's callback thread, each joint ``i`` scaled into
    0..127 (``MIDI_RANGE``) and, if its number changed, sent as control change 20 + i on
    channel 1 through a python-rtmidi virtual output port on JACK (the default server).

    The node beyond it: each frame checked by the gate and counted, the robot's info (its
    joints' ranges and order), events as notes, presence (a robot's silence warned of), the
    latency of each frame noted; its idle Pepper sends ~10 messages a second where this floor's
    sine frames send more (a send is a few µs)."""
    import msgpack
    import rtmidi

    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "midi-floor")
    out.open_virtual_port("floor")
    low, high = MIDI_RANGE
    last: dict[tuple[str, int], int] = {}

    def take(sample: Any) -> None:
        robot, frame = str(sample.key_expr).partition("/")[0], msgpack.unpackb(sample.payload.to_bytes())
        for i, value in enumerate(frame["v"]):
            number = round(min(1.0, max(0.0, (value - low) / (high - low))) * 127)
            if last.get((robot, i)) != number:
                last[robot, i] = number
                out.send_message([0xB0, 20 + i, number])

    try:
        subscribed(endpoint, take, ready, done)
    finally:
        out.close_port()
        out.delete()


# the features floor's robot: a Pepper's joint table as the floor's frames carry it (J0..J16 in
# Pepper's order), its chains, arms and their geometry (the features node's, from its model)
PEPPER_CHAINS = {"Head": (0, 1), "LArm": (2, 3, 4, 5, 6, 7), "Leg": (8, 9, 10), "RArm": (11, 12, 13, 14, 15, 16)}
PEPPER_ARMS = (((-0.057, 0.14974, 0.08682), (2, 3, 4, 5, 6), 0.015), ((-0.057, -0.14974, 0.08682),
                                                                       (11, 12, 13, 14, 15), -0.015))
PEPPER_VMAX = (7.34, 9.23, 7.34, 9.23, 7.34, 9.23, 17.38, 12.56, 2.27, 2.93, 2.93, 7.34, 9.23, 7.34, 9.23, 17.38,
               12.56)


class FloorVelocity:
    """Velocities of ``n`` signals: the features node's filter (a first-order low-pass of
    each step's mean velocity, slope-corrected, from the samples' own times) in plain floats,
    refusing jumps faster than ``rate`` per signal."""

    def __init__(self, n: int, cutoff_hz: float = 5.0, rates: tuple[float, ...] | None = None) -> None:
        import math
        self.tau, self.rates = 1.0 / (2.0 * math.pi * cutoff_hz), rates or (math.inf,) * n
        self.values, self.last_q, self.last_r, self.last_t = [0.0] * n, [math.nan] * n, [0.0] * n, math.nan
        self.last_dt = 1.0

    def step(self, t: float, q: list[float]) -> bool:
        """Take ``q`` at ``t``; whether ``values`` hold velocities for ``t``."""
        import math
        dt = t - self.last_t
        fresh = 0.0 < dt <= 0.5
        if fresh:
            tau, e = self.tau, math.exp(-dt / self.tau)
            delta = dt / 2 - tau + dt * e / (1.0 - e)
            values, last_r, span = self.values, self.last_r, (dt + self.last_dt) / 2
            for i, (x, was, rate) in enumerate(zip(q, self.last_q, self.rates, strict=True)):
                moved = x - was
                if not abs(moved) <= rate * dt:
                    values[i] = 0.0
                    continue
                r = moved / dt
                v = e * values[i] + (1.0 - e) * (r + (r - last_r[i]) / span * delta)
                values[i], last_r[i] = (v if abs(v) >= 1e-9 else 0.0), r
            self.last_dt = dt
        self.last_q, self.last_t = list(q), t
        return fresh


def features_floor(endpoint: str, reader: str, ready: Any, done: Any) -> None:
    """Each frame decoded (msgpack) on Zenoh's callback thread, its default features worked out
    as the features node's plain-float step does — 17 joint velocities (``FloorVelocity``), both
    hands' positions (forward kinematics of each arm's 5 joints, one vector turned per joint), their
    speeds (a velocity filter of the 6 coordinates), the quantity of motion of each chain and of the
    body, motion onsets and offsets of each chain (hysteresis) — each clamped into a range, and put
    as one derived frame (``{t, seq, names, v}``, msgpack) on ``<robot>/derived``, to the
    ``derived_reader``s, the first listening on ``reader``.

    The node beyond it: each frame checked by the gate and counted, a robot's info worked out
    into its tables and served on ``<robot>/info/derived``, missing and refused joints counted
    and warned of, stale frames skipped, each frame's latency noted; its derived frames go to
    every sink that takes them; so do the floor's (``DERIVED_TAKERS`` sessions)."""
    import math

    import msgpack
    import zenoh

    session = zenoh.open(zenoh_config(listen=endpoint, connect=reader))
    publishers: dict[str, Any] = {}
    joints = len(PEPPER_VMAX)
    velocity = FloorVelocity(joints, rates=tuple(10 * v for v in PEPPER_VMAX))
    hands = FloorVelocity(6)
    groups = [*PEPPER_CHAINS.items(), ("Body", tuple(range(joints)))]
    names = ([f"velocity/J{j}" for j in range(joints)] + ["hand/L", "hand/R", "hand_speed/L", "hand_speed/R"]
             + [f"qom/{g}" for g, _ in groups])
    moving = {g: False for g in PEPPER_CHAINS}
    events: list[dict[str, Any]] = []

    def hand(base: tuple[float, float, float], arm: tuple[int, ...], y: float, q: list[float]) -> list[float]:
        # from the hand inwards: wrist yaw (x), elbow roll (z), elbow yaw (x), shoulder roll (z, its
        # offset tilted), shoulder pitch (y)
        c, s = math.cos(q[arm[4]]), math.sin(q[arm[4]])
        px, py, pz = 0.025, 0.0, 0.0
        px, py, pz = px, c * py - s * pz, s * py + c * pz
        c, s = math.cos(q[arm[3]]), math.sin(q[arm[3]])
        ux = 0.15 + px
        px, py, pz = c * ux - s * py, s * ux + c * py, pz
        c, s = math.cos(q[arm[2]]), math.sin(q[arm[2]])
        px, py, pz = px, c * py - s * pz, s * py + c * pz
        ux = 0.1812 + 0.98769 * px - 0.15643 * pz
        uy, uz = y + py, 0.00013 + 0.15643 * px + 0.98769 * pz
        c, s = math.cos(q[arm[1]]), math.sin(q[arm[1]])
        px, py, pz = c * ux - s * uy, s * ux + c * uy, uz
        c, s = math.cos(q[arm[0]]), math.sin(q[arm[0]])
        return [base[0] + c * px + s * pz, base[1] + py, base[2] + c * pz - s * px]

    def take(sample: Any) -> None:
        robot, frame = str(sample.key_expr).partition("/")[0], msgpack.unpackb(sample.payload.to_bytes())
        t, q = frame["t"], [float(x) for x in frame["v"]]
        if not velocity.step(t, q):
            return
        v = [min(hi, max(-hi, x)) for x, hi in zip(velocity.values, PEPPER_VMAX, strict=True)]
        points = [x for base, arm, y in PEPPER_ARMS for x in hand(base, arm, y, q)]
        hands.step(t, points)
        hv = hands.values
        speeds = [min(10.0, math.sqrt(hv[i] * hv[i] + hv[i + 1] * hv[i + 1] + hv[i + 2] * hv[i + 2]))
                  for i in (0, 3)]
        qoms = [sum([abs(v[j]) for j in members], 0.0) for _, members in groups]
        for (group, _), qom in zip(groups, qoms, strict=True):
            if group in moving and moving[group] != (qom > (0.2 if moving[group] else 0.5)):
                moving[group] = not moving[group]
                events.append({"t": t, "kind": "motion", "chain": group, "seq": frame["seq"],
                               "state": "started" if moving[group] else "stopped"})
        key = f"{robot}/derived"
        publisher = publishers.get(key) or publishers.setdefault(key, session.declare_publisher(key))
        publisher.put(msgpack.packb({"t": t, "seq": frame["seq"], "names": names,
                                     "v": [*v, points[:3], points[3:], *speeds, *qoms]}))
        while events:
            session.put(f"{robot}/events/motion", msgpack.packb(events.pop()))

    subscriber = session.declare_subscriber("*/frame", take)
    ready.set()
    done.wait()
    subscriber.undeclare()
    for publisher in publishers.values():
        publisher.undeclare()
    session.close()


def derived_reader(endpoint: str, ready: Any, fed: Any, done: Any) -> None:
    """The features floor's ``DERIVED_TAKERS`` subscribers of derived frames (not measured), one
    process: the first listens on ``endpoint``, the others connect to it (the floor's session
    learns them by gossip and links to each, as the node's links to each sink's); ``ready`` once
    they subscribe, ``fed`` once each has had a derived frame."""
    import zenoh
    sessions = [zenoh.open(zenoh_config(listen=endpoint))]
    sessions += [zenoh.open(zenoh_config(connect=endpoint)) for _ in range(DERIVED_TAKERS - 1)]
    got = [threading.Event() for _ in sessions]
    subscribers = [session.declare_subscriber("*/derived", lambda sample, event=event: event.set())
                   for session, event in zip(sessions, got, strict=True)]
    ready.set()
    if all(event.wait(60) for event in got):  # (else said by the caller: fed is never set)
        fed.set()
    done.wait()
    for subscriber, session in zip(subscribers, sessions, strict=True):
        subscriber.undeclare()
        session.close()


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


def measure(seconds: float, warmup_s: float = 3.0, nodes: tuple[str, ...] = NODES) -> dict[str, float]:
    """CPU % of one core of each floor (of ``nodes``) over ``seconds`` after ``warmup_s``, each
    fed its own publisher of one robot × 17 joints at ``RATE_HZ`` (with a derived frame beside
    each for the floors of ``FED_DERIVED``)."""
    with running(nodes, seconds + warmup_s + 1) as pids:
        time.sleep(warmup_s)
        before, started = {name: cpu_ns(pid) for name, pid in pids.items()}, time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - started
        return {name: 100.0 * (cpu_ns(pid) - before[name]) / 1e9 / wall for name, pid in pids.items()}


@contextlib.contextmanager
def running(nodes: tuple[str, ...] = NODES, seconds: float = 600.0, links: Links | None = None,
            served: set[int] | None = None) -> Iterator[dict[str, int]]:
    """The floors of ``nodes`` running, each fed (``measure``'s), for ``seconds`` at most: their
    process ids by node, once every floor is fed (not warmed up); stopped on leaving. With
    ``links`` (``bench/links.py``), each floor's process can be given idle links; ``served``:
    filled with the ports its WebSocket clients connect to."""
    if not nodes:
        yield {}
        return
    done = CONTEXT.Event()
    endpoints = {name: f"tcp/127.0.0.1:{free_port()}" for name in nodes}
    web_ports = {name: free_port() for name in ("foxglove", "oscquery", "web") if name in nodes}  # (each with a client)
    if served is not None:
        served.update(web_ports.values())
    readies = {name: CONTEXT.Event() for name in (*endpoints, *(f"{name} client" for name in web_ports))}
    derived, derived_at = CONTEXT.Event(), f"tcp/127.0.0.1:{free_port()}"  # (the features floor's readers)
    derived_fed = CONTEXT.Event()
    with tempfile.TemporaryDirectory() as folder:
        targets = {"foxglove": (foxglove_floor, (web_ports.get("foxglove"),)), "recorder": (recorder_floor, (folder,)),
                   "oscquery": (oscquery_floor, (web_ports.get("oscquery"),)),
                   "web": (web_floor, (web_ports.get("web"),)), "midi": (midi_floor, ()),
                   "features": (features_floor, (derived_at,))}
        floors = {name: Links.process(links, name, target, (endpoints[name], *where, readies[name], done))
                  for name, (target, where) in targets.items() if name in nodes}
        others: list[Any] = []
        feeders: list[Any] = []
        if "features" in nodes:
            others.append(CONTEXT.Process(target=derived_reader, args=(derived_at, derived, derived_fed, done),
                                          daemon=True))
        else:
            derived.set()
            derived_fed.set()
        try:
            for process in (*others, *floors.values()):
                process.start()
            if not all(readies[name].wait(30) for name in floors):
                raise RuntimeError("the node floors did not start")
            for name, port in web_ports.items():
                others.append(CONTEXT.Process(target=reader, args=(port, readies[f"{name} client"], done),
                                              daemon=True))
                others[-1].start()
            if not all(readies[f"{name} client"].wait(30) for name in web_ports) or not derived.wait(30):
                raise RuntimeError("the node floors' clients did not connect")
            handles = []  # (kept until the end: a queue collected here is gone for the child too)
            for name, endpoint in endpoints.items():
                fed, out = CONTEXT.Event(), CONTEXT.Queue()
                feeders.append(CONTEXT.Process(target=publish, args=(endpoint, Case(1, 17), seconds, fed, out),
                                               daemon=True,
                                               kwargs={"rate_hz": RATE_HZ, "derived": name in FED_DERIVED}))
                feeders[-1].start()
                handles.append((fed, out))
            if not all(fed.wait(30) for fed, _ in handles) or not derived_fed.wait(30):
                raise RuntimeError("the node floors' publishers did not find their subscribers")
            yield {name: p.pid for name, p in floors.items()}
        finally:
            done.set()
            for process in feeders:  # (they would publish until their time is up)
                process.kill()
            for process in (*others, *floors.values()):
                if process.pid is None:  # (never started)
                    continue
                process.join(10)
                if process.is_alive():
                    process.kill()


if __name__ == "__main__":
    print(json.dumps(measure(4.0, 2.0), indent=1))
