"""The clients of the show soak (``soak_show.py``), which come and go in cycles: an
operator page and a kiosk (WebSockets of the web node, sending commands and presses),
an OSCQuery client (the namespace over HTTP, LISTENs over its WebSocket), a Foxglove
client subscribing to every channel, OSC receivers at the sink's targets, an OSC
program sending the gateway commands (and show scenarios) from a fresh port each
cycle, and a JACK MIDI reader of the midi node.

``Clients.cycle(seconds)`` attaches them all for ``seconds`` then lets them go; what
they did is counted in ``Clients.counts``, errors kept (a few) in ``Clients.errors``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass

import aiohttp

JOINTS = ("HeadYaw", "HeadPitch", "LShoulderPitch", "RShoulderPitch", "LElbowRoll", "RElbowRoll")
BEHAVIOR = "animations/Stand/Gestures/Hey_1"
POSTURES = ("StandInit", "Stand")


@dataclass(frozen=True)
class Endpoints:
    """Where the show's nodes are reached (all on 127.0.0.1)."""

    web: int
    oscquery: int
    foxglove: int
    gateway: int
    osc_targets: tuple[int, ...]
    robot: str = "pepper"
    button: str = "hey"
    scenario: str = ""          # a show scenario to ask for over OSC ("": no show node)
    midi_port: str = ""         # a JACK MIDI output to read ("": no midi node)


def osc_message(address: str, *args: str | float) -> bytes:
    """An OSC message of strings and floats (the gateway's commands need no more)."""
    def pad(b: bytes) -> bytes:
        b += b"\0"
        return b + b"\0" * (-len(b) % 4)
    tags = "," + "".join("s" if isinstance(a, str) else "f" for a in args)
    body = b"".join(pad(a.encode()) if isinstance(a, str) else struct.pack(">f", a) for a in args)
    return pad(address.encode()) + pad(tags.encode()) + body


class Clients:
    """Every kind of client of the show, attached for a cycle at a time."""

    def __init__(self, at: Endpoints, seed: int = 0) -> None:
        self.at = at
        self.random = random.Random(seed)
        self.counts: Counter[str] = Counter()
        self.errors: list[str] = []
        self._ids = 0

    def cycle(self, seconds: float) -> None:
        """Attach every client for ``seconds``, then close them all."""
        asyncio.run(self._cycle(seconds))

    # -- one cycle -------------------------------------------------------------------------

    async def _cycle(self, seconds: float) -> None:
        stop = asyncio.Event()
        receivers = [_Receiver(port) for port in self.at.osc_targets]
        midi = _midi_reader(self.at.midi_port) if self.at.midi_port else None
        timeout = aiohttp.ClientTimeout(total=None, sock_connect=5)
        try:
            async with aiohttp.ClientSession(timeout=timeout) as session:
                jobs = [self._page(session, stop), self._kiosk(session, stop), self._oscquery(session, stop),
                        self._foxglove(session, stop), self._gateway(stop)]
                tasks = [asyncio.create_task(job) for job in jobs]
                await asyncio.sleep(seconds)
                stop.set()
                for outcome in await asyncio.gather(*tasks, return_exceptions=True):
                    if isinstance(outcome, BaseException):
                        self._error(outcome)
        finally:
            for receiver in receivers:
                self.counts["osc_received"] += receiver.close()
            if midi is not None:
                try:
                    self.counts["midi_received"] += midi.close()
                except RuntimeError as exc:
                    self._error(exc)
        self.counts["cycles"] += 1

    def _error(self, exc: BaseException) -> None:
        self.counts["client_errors"] += 1
        if len(self.errors) < 20:
            self.errors.append(f"{time.strftime('%H:%M:%S')} {type(exc).__name__}: {exc}")

    def _id(self) -> int:
        self._ids += 1
        return self._ids

    def _origin(self) -> dict[str, str]:
        return {"origin": f"http://127.0.0.1:{self.at.web}"}

    # -- the operator's page: commands of every kind, sliders in bursts, now and then a stop --

    async def _page(self, session: aiohttp.ClientSession, stop: asyncio.Event) -> None:
        async with session.ws_connect(f"ws://127.0.0.1:{self.at.web}/ws", **self._origin()) as ws:
            self.counts["page_connects"] += 1
            reader = asyncio.create_task(self._drain(ws, "page_messages", stop))
            robot = self.at.robot
            while not stop.is_set():
                verb = self.random.choice(("say", "joints/set", "joints/set", "posture", "behavior/run", "stop"))
                if verb == "stop":
                    await ws.send_str(json.dumps({"type": "stop", "id": self._id()}))
                elif verb == "joints/set":  # a slider dragged: a burst the page coalesces
                    joint = self.random.choice(JOINTS)
                    for _ in range(10):
                        args = {"names": [joint], "angles": [self.random.uniform(-0.3, 0.3)]}
                        await ws.send_str(json.dumps({"type": "command", "id": self._id(), "robot": robot,
                                                      "verb": verb, "args": args}))
                        await asyncio.sleep(0.02)
                else:
                    args = {"say": {"text": f"hello {self._ids}"}, "posture": {"name": self.random.choice(POSTURES)},
                            "behavior/run": {"name": BEHAVIOR}}[verb]
                    await ws.send_str(json.dumps({"type": "command", "id": self._id(), "robot": robot,
                                                  "verb": verb, "args": args}))
                self.counts[f"page_{verb}"] += 1
                await _pause(stop, 2.0)
            reader.cancel()

    async def _drain(self, ws: aiohttp.ClientWebSocketResponse, counter: str, stop: asyncio.Event) -> None:
        while not stop.is_set():
            message = await ws.receive()
            if message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                if not stop.is_set():
                    raise ConnectionError(f"{counter}: the server closed the WebSocket ({message.data})")
                return
            self.counts[counter] += 1

    # -- the kiosk: a visitor's press now and then ----------------------------------------------

    async def _kiosk(self, session: aiohttp.ClientSession, stop: asyncio.Event) -> None:
        async with session.ws_connect(f"ws://127.0.0.1:{self.at.web}/kiosk/ws", **self._origin()) as ws:
            self.counts["kiosk_connects"] += 1
            reader = asyncio.create_task(self._drain(ws, "kiosk_messages", stop))
            while not stop.is_set():
                await ws.send_str(json.dumps({"type": "press", "id": self._id(), "button": self.at.button}))
                self.counts["kiosk_presses"] += 1
                await _pause(stop, 8.0)
            reader.cancel()

    # -- OSCQuery: the namespace, then LISTENs to a few joints, one IGNOREd and LISTENed again --

    async def _oscquery(self, session: aiohttp.ClientSession, stop: asyncio.Event) -> None:
        base = f"127.0.0.1:{self.at.oscquery}"
        async with session.get(f"http://{base}/") as answer:
            await answer.read()
            self.counts["oscquery_namespaces"] += 1
        async with session.ws_connect(f"ws://{base}/") as ws:
            self.counts["oscquery_connects"] += 1
            for joint in JOINTS:
                await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": f"/{self.at.robot}/joints/{joint}"}))
            reader = asyncio.create_task(self._drain(ws, "oscquery_messages", stop))
            while not stop.is_set():
                path = f"/{self.at.robot}/joints/{self.random.choice(JOINTS)}"
                await ws.send_str(json.dumps({"COMMAND": "IGNORE", "DATA": path}))
                await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": path}))
                self.counts["oscquery_listens"] += 1
                await _pause(stop, 5.0)
            reader.cancel()

    # -- Foxglove: subscribe to every channel advertised ------------------------------------------

    async def _foxglove(self, session: aiohttp.ClientSession, stop: asyncio.Event) -> None:
        async with session.ws_connect(f"ws://127.0.0.1:{self.at.foxglove}",
                                      protocols=("foxglove.websocket.v1",)) as ws:
            self.counts["foxglove_connects"] += 1
            subscribed: set[int] = set()
            while not stop.is_set():
                try:
                    message = await asyncio.wait_for(ws.receive(), 1.0)
                except TimeoutError:
                    continue
                if message.type == aiohttp.WSMsgType.TEXT:
                    data = json.loads(message.data)
                    if data.get("op") == "advertise":
                        new = [c["id"] for c in data["channels"] if c["id"] not in subscribed]
                        subscribed.update(new)
                        if new:
                            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
                                {"id": self._id(), "channelId": c} for c in new]}))
                            self.counts["foxglove_subscriptions"] += len(new)
                elif message.type == aiohttp.WSMsgType.BINARY:
                    self.counts["foxglove_messages"] += 1
                elif message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                    raise ConnectionError(f"foxglove: the server closed the WebSocket ({message.data})")

    # -- an OSC program: gateway commands (and scenarios) from a fresh port each cycle -------------

    async def _gateway(self, stop: asyncio.Event) -> None:
        robot, to = self.at.robot, ("127.0.0.1", self.at.gateway)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            s.setblocking(False)
            while not stop.is_set():
                choice = self.random.choice(("say", "joint", "posture", "behavior", "scenario", "stop"))
                packet = {
                    "say": lambda: osc_message(f"/{robot}/cmd/say", f"osc {self._id()}"),
                    "joint": lambda: osc_message(f"/{robot}/cmd/joints/set/{self.random.choice(JOINTS)}",
                                                 self.random.uniform(-0.3, 0.3)),
                    "posture": lambda: osc_message(f"/{robot}/cmd/posture", self.random.choice(POSTURES)),
                    "behavior": lambda: osc_message(f"/{robot}/cmd/behavior/run", BEHAVIOR),
                    "scenario": lambda: (osc_message(f"/{robot}/program/scenario", self.at.scenario)
                                         if self.at.scenario else osc_message(f"/{robot}/cmd/behavior/stop")),
                    "stop": lambda: osc_message(f"/{robot}/cmd/stop"),
                }[choice]()
                s.sendto(packet, to)
                self.counts[f"gateway_{choice}"] += 1
                await _pause(stop, 3.0)
                with contextlib.suppress(BlockingIOError):
                    while True:
                        s.recv(65536)
                        self.counts["gateway_replies"] += 1


async def _pause(stop: asyncio.Event, seconds: float) -> None:
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), seconds)


class _Receiver:
    """A UDP socket at an OSC target, counting what arrives until closed (then the port is
    closed: the sink's sends there are refused, as when a sound tool quits)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.2)
        self.received = 0
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.is_set():
            with contextlib.suppress(TimeoutError):
                self.sock.recv(65536)
                self.received += 1

    def close(self) -> int:
        self._done.set()
        self._thread.join(2.0)
        self.sock.close()
        return self.received


_MIDI_CHILD = r"""
import os, sys, rtmidi
midi = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "soak-reader")
wanted = [i for i, name in enumerate(midi.get_ports()) if sys.argv[1] in name]
if not wanted:
    print("none", flush=True)
    os._exit(0)
count = [0]
midi.set_callback(lambda event, data: count.__setitem__(0, count[0] + 1))
midi.open_port(wanted[0], "in")
print("ready", flush=True)
sys.stdin.read()  # (until the soak closes it)
print(count[0], flush=True)
midi.close_port()
midi.delete()
"""


class _MidiReader:
    """A JACK MIDI input (python-rtmidi) in a process of its own: rtmidi's JACK backend
    crashed the soak itself (SIGSEGV in _rtmidi, a callback thread, 24 minutes into a
    long form) — a client's crash must cost one cycle's count, not the run."""

    def __init__(self, port: str) -> None:
        self.child = subprocess.Popen([sys.executable, "-c", _MIDI_CHILD, port], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, text=True)
        assert self.child.stdout is not None
        self.ready = self.child.stdout.readline().strip()  # "ready", "none" (no such port), "" (it died)

    def close(self) -> int:
        """The events it read; an exception if it did not end well."""
        try:
            out, _ = self.child.communicate("", timeout=10)
        except subprocess.TimeoutExpired:
            self.child.kill()
            self.child.wait()
            raise RuntimeError("midi reader: not ended 10 s after its stdin closed (killed)") from None
        if self.child.returncode != 0 or not out.strip().isdigit():
            raise RuntimeError(f"midi reader: exit {self.child.returncode}, said {out.strip()[-200:]!r}")
        return int(out.strip())


def _midi_reader(port: str) -> _MidiReader | None:
    """A JACK MIDI input connected to ``port``, or None when the port is not there."""
    reader = _MidiReader(port)
    if reader.ready == "ready":
        return reader
    with contextlib.suppress(RuntimeError):
        reader.close()
    return None
