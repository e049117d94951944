"""``foxglove``: the bus live in Foxglove, over its WebSocket protocol (``wire.py``).

    [nodes.foxglove]
    adapter = "foxglove"
    listen = "127.0.0.1:8765"     # Foxglove → Open connection → ws://localhost:8765

It serves what a recording holds (unless made with ``foxglove = false``), as channels named by
their keys: the joints, derived values and events ``subscribe`` selects, each
robot's ``<robot>/info``, and the views of ``views.py`` (``<robot>/frame``,
``<robot>/log``, ``<robot>/tf``, ``<robot>/info/derived``). A channel is
advertised with its first message, which a subscription gets first (``hub.py``); a
message is encoded only for channels a client subscribes to. Info and info/derived
are sent again every ``info_every_s``, so a client that connects later gets them.
When a robot leaves the bus (its owner's token goes) its channels are unadvertised, and
advertised anew with its first messages when it comes back.

Served on ``bus/web.py``'s ``WebServer``, not foxglove-sdk's server (docs/foxglove.md,
"Why not foxglove-sdk's server"): that one refuses ``foxglove.websocket.v1`` clients,
advertises a channel before it can be subscribed to, stops accepting for good on the
first failed ``accept`` (EMFILE), and has no limits, timeouts or ``Origin`` check.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from importlib.metadata import version
from typing import Any

from sonibus.adapters.osc.gateway import parse_endpoint
from sonibus.adapters.recorder.channels import MESSAGE_ENCODING, SCHEMA_ENCODING, channel_schema
from sonibus.bus import codec, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.info import InfoRequests
from sonibus.bus.options import bad
from sonibus.bus.plan import without_audio
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams
from sonibus.bus.web import Limits, WebServer

from . import wire
from .framed import Handoff
from .hub import MAX_CHANNELS, Hub
from .views import DERIVED_INFO, LOG, Views, samples_of

log = logging.getLogger(__name__)

MAX_ROBOTS = 64  # robots served (names made up on the bus must not grow what is kept per robot)
MAX_GONE = 1024  # robots remembered as gone (names from the bus: a claim storm must not grow it for ever)
GATHER_S = 0.02  # frames gathered on the server's loop this long at most (Handoff: a frame and its derived frame
                 # in one wake-up and one write to a client; a viewer draws at 60 Hz at most)


@dataclass(frozen=True)
class FoxgloveConfig:
    """Options of the ``foxglove`` adapter."""

    listen: str = "127.0.0.1:8765"            # host:port of the WebSocket ("0.0.0.0:8765": every interface; 0: any)
    subscribe: tuple[str, ...] = ("*/joints/*", "*/derived/**", "*/events/*")  # robot info is always served
    name: str = "sonibus"                     # the server's name, shown by Foxglove
    per_joint_keys: bool = False              # joints from <robot>/joints/* instead of <robot>/frame
    queue: int = 4096                         # messages waiting to be served; past this the oldest are dropped
    info_every_s: float = 5.0                 # info and info/derived sent again this often (later clients)
    limits: Limits = field(default_factory=Limits)  # [nodes.<name>.limits]: connections, clients, timeout_s
    origins: tuple[str, ...] = ("https://app.foxglove.dev",)  # web pages that may connect (browsers send Origin)

    def __post_init__(self) -> None:
        parse_endpoint("listen", self.listen)
        # (Foxglove's JSON channels have no form for PCM: an audio chunk would stop the node)
        object.__setattr__(self, "subscribe", without_audio(keys.patterns(self.subscribe), "the foxglove adapter"))
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        if not self.info_every_s > 0:
            raise bad("info_every_s", f"{self.info_every_s} must be more than 0 (seconds)")


class FoxgloveServer(Adapter):
    """Robots live in Foxglove: joints, frames, arm transforms and events as logs, over its WebSocket protocol."""

    Config = FoxgloveConfig
    # sent: messages to clients (one per subscriber); writes: transport writes that sent them (several messages
    # each); clients: connections so far; dropped_for_clients: lost by a client that does not read
    counters = ("sent", "writes", "clients", "dropped_for_clients")

    def __init__(self, config: FoxgloveConfig | None = None, *, name: str = "") -> None:
        super().__init__(config, name=name)
        self.port = 0  # the port bound, once started

    def _start(self) -> None:
        cfg: FoxgloveConfig = self.config
        host, port = parse_endpoint("listen", cfg.listen)
        self.web = WebServer(self, host, port, key="listen", limits=cfg.limits, browsers=True, origins=cfg.origins)
        self.hub = Hub(self, self.web, cfg.name, wire.to_json, {"sonibus": version("sonibus")})
        self._infos: dict[str, dict[str, Any]] = {}  # info and info/derived keys → their latest message
        self._queue = self.own(SampleQueue(cfg.queue))
        self._info_seen: set[str] = set()
        self._robots: set[str] = set()  # robots served: their messages pass, and their state is kept
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: self.warn("info", text))
        self._views = Views(self.bus, self._take_derived_info)
        # Frames are handed to the server's loop as they arrive and served there (issue 35: the loop wakes for
        # them anyway, and a Zenoh thread that made their JSON fought it for the GIL), the rest from the queue by
        # the serve worker; one lock between them guards the node's state and the order of its messages.
        self._state = threading.Lock()
        self._streams: Streams | None = None  # (a frame that arrives while Streams subscribes: queued)
        self._handoff = Handoff(self.web, self._arrivals, gather_s=GATHER_S)
        self._streams = Streams(self.bus, cfg.subscribe, self._queue, per_joint_keys=cfg.per_joint_keys,
                                direct=self._direct)
        self._comings: deque[tuple[str, bool]] = deque(maxlen=4096)  # robots come or gone (a Zenoh thread)
        self._gone: dict[str, None] = {}  # robots gone and not back: what of them is still in flight is dropped
        self.own(watch_robots(self.bus, self._coming, self.capped))
        self.web.start()
        self.port = self.web.port
        self.address = (f"Foxglove → Open connection → ws://"
                        f"{'localhost' if host in ('127.0.0.1', '0.0.0.0') else host}:{self.port}")
        log.info("%s: %s", self.name, self.address)
        self.when_stopping(self._queue.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._serve, "serve")

    def _stop(self) -> None:
        if hasattr(self, "_streams"):
            self._streams.undeclare()

    def metrics(self) -> dict[str, Any]:
        """The port, the channels advertised and the clients connected."""
        hub = getattr(self, "hub", None)
        return {"port": self.port, "channels": hub.channels if hub else 0, "clients": hub.clients if hub else 0}

    def _take_info(self, robot: str, info: dict[str, Any]) -> None:  # on a Zenoh thread
        self._queue.put((keys.info(robot), codec.encode(info)))

    def _take_derived_info(self, key: str, payload: bytes) -> None:  # on a Zenoh thread
        self._queue.put((key, payload))

    def _coming(self, robot: str, alive: bool) -> None:  # on a Zenoh thread
        """A robot came or went: noted, and the serve worker woken for it (``SampleQueue.wake``)."""
        self._comings.append((robot, alive))
        self._queue.wake()

    def _serve(self) -> None:
        """The queue's messages and the robots come or gone, as they come; the infos sent again
        every ``info_every_s`` (the only time it wakes by itself); until the stop closes the queue."""
        again = time.monotonic() + self.config.info_every_s
        while not self.stopping.is_set():
            items = self._queue.drain(timeout=max(0.0, again - time.monotonic()))
            with self._state:
                self._changes()
                for item in items:
                    if item[0].partition("/")[0] not in self._gone:
                        self._take(*item)
                if time.monotonic() >= again:
                    again = time.monotonic() + self.config.info_every_s
                    for key, message in list(self._infos.items()):
                        self._log(key, message)

    def _direct(self, key: str, payload: Any) -> bool:
        """A frame, on its subscription's callback thread (``Streams``' ``direct``): handed to the
        server's loop (``Handoff``: ``_arrivals``), or into the queue (False)."""
        return self._streams is not None and self._handoff.put(key, payload)

    def _arrivals(self, arrived: list[tuple[str, Any]]) -> None:
        """Frames served on the server's loop; what they give the clients handed to them at
        the end, in one go (``Hub.batch``)."""
        with self.hub.batch(), self._state:
            for key, payload in arrived:
                self._serve_one(key, payload)

    def _serve_one(self, key: str, payload: Any) -> None:  # (holding _state)
        self._changes()
        if key.partition("/")[0] not in self._gone:
            self._take(key, payload)

    def _changes(self) -> None:  # (holding _state)
        """Robots come or gone, before any message: those of a robot gone are dropped, not advertised again."""
        while self._comings:
            self._robot_changed(*self._comings.popleft())

    def _robot_changed(self, robot: str, alive: bool) -> None:
        """A robot gone: its channels unadvertised, what was kept of it forgotten (its info is asked
        for again when it comes back)."""
        if alive:
            self._gone.pop(robot, None)
            return
        if len(self._gone) >= MAX_GONE:
            del self._gone[next(iter(self._gone))]
        self._gone[robot] = None
        self._robots.discard(robot)  # (its place among the MAX_ROBOTS served is free again)
        self._info_seen.discard(robot)
        self._views.derived_seen.discard(robot)
        self._infos = {k: v for k, v in self._infos.items() if k.partition("/")[0] != robot}
        forgotten = self.hub.forget(f"{robot}/")
        if forgotten:  # (a claim that never sent anything, made up or not, is not worth a line)
            log.info("%s: robot '%s' left the bus: %d channels unadvertised", self.name, robot, forgotten)

    def _take(self, key: str, payload: bytes) -> None:
        if key.endswith("/" + DERIVED_INFO):
            try:
                self._infos[key] = self._views.derived_info(key, payload)
            except ValueError as exc:  # messages.BadMessage
                self.count("bad")
                self.warn("bad", f"message on '{key}' refused: {exc}")
                return
            self._log(key, self._infos[key])
            return
        incoming = self._streams.take(key, payload, self.count, self.warn)  # checked by the gate, counted
        if incoming is None:
            return
        robot = incoming.source.robot
        if robot not in self._robots:
            if len(self._robots) >= MAX_ROBOTS:  # (its info, arms, views: per robot)
                self.capped(f"robot '{robot}' not served: already {MAX_ROBOTS} robots")
                return
            self._robots.add(robot)
        if key.endswith("/info"):
            self._info_seen.add(robot)
            self._infos[key] = incoming.message
        elif robot not in self._info_seen:
            self._info.ask(robot)
        # (an event's channels, its own and <robot>/log, keep a history: Hub.log's)
        self._log_all([*samples_of(incoming), *self._views.of(incoming)], incoming.source.section == "events")

    def _log(self, key: str, message: dict[str, Any]) -> None:
        """``message`` on the channel of ``key`` (advertised now if new), to the clients subscribed."""
        self._log_all([(key, message)], _events(key))

    def _log_all(self, messages: list[tuple[str, dict[str, Any]]], events: bool) -> None:
        """Each ``(key, message)`` on its channel, in one go (``Hub.log_all``); ``events``: all of
        them on channels of events (``_events``)."""
        problems = self.hub.log_all(messages, time.time_ns(), _describe, events)
        for key, exc in problems:
            if exc is None:
                self.warn("channels", f"'{key}' not served: {MAX_CHANNELS} channels already")
            else:  # (past the gate: rare) not strict JSON
                self.count("bad")
                self.warn("unsendable", f"message on '{key}' not sent: {exc}")


def _events(key: str) -> bool:
    """Whether the channel of ``key`` carries events (a robot's events, its ``log`` view): every
    message of it counts, not only the latest (``Hub.log``'s ``history``)."""
    section = key.split("/", 2)[1:2]
    return section == ["events"] or key.partition("/")[2] == LOG


def _describe(id_: int, key: str) -> wire.Channel:
    """The channel of ``key``: its schema when sonibus has one (a JSON Schema), else none (any JSON)."""
    found = channel_schema(key)
    name, schema = (found[0], found[1].decode()) if found else ("", "")
    return wire.Channel(id_, key, MESSAGE_ENCODING, name, schema, SCHEMA_ENCODING if found else "")
