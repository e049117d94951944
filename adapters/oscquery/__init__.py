"""OSCQuery server (adapter ``oscquery``): the live namespace of every robot on the bus,
for sound tools that discover OSC services (ossia score, Chataigne, TouchDesigner, Max).

    [nodes.oscquery]
    adapter = "oscquery"
    listen = "127.0.0.1:5678"
    gateway = "127.0.0.1:9001"   # the osc-gateway: where clients send commands

``curl http://127.0.0.1:5678/?HOST_INFO`` describes the host; ``/pepper/joints/HeadYaw``
a joint (type, range, unit, current value); a WebSocket on the same port streams what a
client LISTENs to as binary OSC, and says PATH_ADDED / PATH_REMOVED / PATH_CHANGED as
robots come, go or change. docs/oscquery.md has it all.
"""

from __future__ import annotations

import ipaddress
import logging
import threading
import time
from typing import Any

from sonibus.adapters.osc import encode
from sonibus.adapters.osc.profiles import event_args
from sonibus.bus.adapter import Adapter
from sonibus.bus.info import DERIVED_ALONE, InfoRequests, watch_nodes
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams, if_free
from sonibus.bus.web import WebServer

from . import mdns
from .config import OscQueryConfig
from .live import Live, span_of, values_of
from .server import QueryServer

__all__ = ["OscQuery", "OscQueryConfig"]

log = logging.getLogger(__name__)

SUBSCRIBE = ("*/joints/*", "*/derived/**", "*/events/*")
MAX_NODES = 4096  # node names remembered (a source of derived values is served while its node is on the bus)
MAX_SERVED = 64  # robots in the namespace (names made up on the bus must not grow it, nor its rebuilds)
INFO_EVERY_S = 2.0  # how often the info of each robot on the bus is asked again (behaviors installed...)
# The spec's optional attributes and notifications, and whether this server gives them.
EXTENSIONS = {"ACCESS": True, "VALUE": True, "RANGE": True, "DESCRIPTION": True, "UNIT": True,
              "LISTEN": True, "PATH_ADDED": True, "PATH_REMOVED": True, "PATH_CHANGED": True,
              "TAGS": False, "CLIPMODE": False, "CRITICAL": False, "EXTENDED_TYPE": False,
              "OVERLOADS": False, "PATH_RENAMED": False, "HTML": False}


class OscQuery(Adapter):
    """Serves every robot on the bus as an OSCQuery namespace over HTTP and WebSocket."""

    Config = OscQueryConfig
    # (values to WebSocket clients: `sent`); ws_dropped: lost by a client that does not read; unfit: an event
    # or value that does not fit its method's TYPE (warned about, not served)
    counters = ("http_requests", "ws_clients", "ws_dropped", "robots_left_out", "unfit")

    def _start(self) -> None:
        cfg: OscQueryConfig = self.config
        self.live = Live(normalized=cfg.values == "normalized", on_unfit=self._unfit)
        self.web = WebServer(self, cfg.host, cfg.port, key="listen", limits=cfg.limits, browsers=True)
        self.server = QueryServer(self, self.web, self.live, self._host_info())
        self._present: set[str] = set()  # robots on the bus (their claims)
        self._alone: set[str] = set()  # sources of derived values that are no robot (map nodes), served
        self._nodes: set[str] = set()  # nodes on the bus (their tokens): a source is served while its node is
        self._left_out: dict[str, int] = {}  # robot → a fingerprint of the unusable info it was left out for
        self._present_lock = threading.Lock()
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: self.warn("info", text),
                                  INFO_EVERY_S, derived_alone=True)
        self.web.start()
        self.url = self.web.url  # the bound one (port 0: any free port)
        self.address = f"OSCQuery on {self.url} (WebSocket on the same port)"
        log.info("%s: %s", self.name, self.address)
        self._queue = self.own(SampleQueue(cfg.queue))
        # Frames are taken where they arrive (a thread hand-off less, as the OSC sink's), the rest from the
        # queue by the forward worker; one lock between them guards what they share (pacing, the namespace's
        # values, what goes to the clients in order).
        self._state = threading.Lock()
        self._streams: Streams | None = None  # (a frame that arrives while Streams subscribes: queued)
        self._streams = Streams(self.bus, SUBSCRIBE, self._queue, direct=self._direct)
        self.spawn(self._forward, "forward")  # before anything else is declared: nothing waits in the queue
        self.own(self._streams)
        self.own(watch_robots(self.bus, self._robot_changed, self.capped))
        self.own(watch_nodes(self.bus, self._node_changed))
        self.spawn(lambda: self._info.keep_asking(self.stopping, self._on_bus), "info")
        if cfg.mdns:
            self._advertise(cfg)
        if _loopback(cfg.gateway_address[0]) and not _loopback(cfg.host):
            log.warning("%s: gateway = %r tells clients on other machines to send commands to themselves — give "
                        "the gateway's address on the network (or \"0.0.0.0:<port>\": this server's address)",
                        self.name, cfg.gateway)

    def _host_info(self) -> dict[str, Any]:
        cfg: OscQueryConfig = self.config
        osc_host, osc_port = cfg.gateway_address
        info: dict[str, Any] = {"NAME": cfg.name, "EXTENSIONS": EXTENSIONS, "OSC_PORT": osc_port,
                                "OSC_TRANSPORT": "UDP"}
        if osc_host not in ("0.0.0.0", "::"):  # (else a client takes this server's address)
            info["OSC_IP"] = osc_host
        return info

    def _advertise(self, cfg: OscQueryConfig) -> None:
        bind = mdns.addresses(cfg.host, cfg.interfaces)
        advertiser = self.own(mdns.Advertiser(cfg.name, bind, self.web.port, *cfg.gateway_address))

        def run() -> None:
            try:
                advertiser.run(self.stopping)
            except Exception as exc:  # no multicast on these interfaces: served, but not advertised
                self.count("errors")
                log.warning("%s: not advertised by mDNS on %s: %s — clients can still connect to %s "
                            "(mdns = false silences this)", self.name, ", ".join(bind), exc, self.url)
        self.spawn(run, "mdns")

    def metrics(self) -> dict[str, Any]:
        """What is served now: robots, WebSocket clients connected, paths listened to."""
        if not hasattr(self, "server"):
            return {}
        return {"robots": len(self.live.robots), "ws_connected": self.server.clients,
                "listened": len(self.server.listened)}

    # -- robots ------------------------------------------------------------------------

    def _robot_changed(self, robot: str, alive: bool) -> None:
        with self._present_lock:  # (with _take_info's: a robot that left is never added back)
            if alive:
                self._present.add(robot)
            else:
                self._present.discard(robot)
                self._drop(robot)
        if alive:
            self._info.ask(robot)

    def _node_changed(self, node: str, alive: bool) -> None:
        with self._present_lock:
            if alive:
                if len(self._nodes) < MAX_NODES:
                    self._nodes.add(node)
                return
            self._nodes.discard(node)
            if node in self._alone and node not in self._present:
                self._alone.discard(node)
                self._drop(node)

    def _drop(self, robot: str) -> None:
        """Take ``robot``'s paths out (its claims or its node went); with ``_present_lock``."""
        self._left_out.pop(robot, None)
        if self.live.drop_robot(robot):
            self.server.announce("PATH_REMOVED", f"/{robot}")
            self.server.announce("PATH_CHANGED", "/")  # (the spec: a method removed changes its parent)

    def _on_bus(self) -> list[str]:
        with self._present_lock:
            return [*self._present, *self._alone]

    def _take_info(self, robot: str, info: dict[str, Any]) -> None:
        with self._present_lock:
            alone = info.get(DERIVED_ALONE) is True and robot not in self._present
            if alone and robot not in self._nodes:  # (its node went while its info was on the way)
                return
            if robot not in self._present and not alone:  # it left while its info was on the way
                return
            if robot not in self.live.robots and len(self.live.robots) >= MAX_SERVED:
                self.capped(f"robot '{robot}' not served: already {MAX_SERVED} robots in the namespace")
                return
            try:
                change = self.live.set_robot(robot, info)
            except (KeyError, TypeError, ValueError) as exc:
                fingerprint = hash(repr(info))  # (not the info itself: up to 1 MiB, for each robot on the bus)
                if self._left_out.get(robot) != fingerprint:  # (counted once per robot, until its info changes)
                    self._left_out[robot] = fingerprint
                    self.count("robots_left_out")
                self.warn(f"info:{robot}", f"robot '{robot}' left out of the namespace: its info is unusable "
                                           f"({type(exc).__name__}: {exc})")
                return
            self._left_out.pop(robot, None)
            if alone:
                self._alone.add(robot)
            if change is not None:
                log.info("%s: %s /%s", self.name, change, robot)
                self.server.announce(change, f"/{robot}")
                if change == "PATH_ADDED":
                    self.server.announce("PATH_CHANGED", "/")

    # -- values ------------------------------------------------------------------------

    def _forward(self) -> None:
        while not self.stopping.is_set():
            item = self._queue.get(timeout=0.2)
            if item is not None:
                with self._state:
                    self._take(*item)

    def _direct(self, key: str, payload: Any) -> bool:
        """A frame, on its subscription's callback thread (``Streams``' ``direct``); into the
        queue instead (False) while the forward worker holds the state (``if_free``)."""
        return self._streams is not None and if_free(self._state, lambda: self._take(key, payload))

    def _take(self, key: str, payload: Any) -> None:  # (holding _state)
        message = self._streams.take(key, payload, self.count, self.warn)  # checked by the gate, paced
        if message is not None:
            self._serve(message)

    def _serve(self, message: Incoming) -> None:
        """An event at once; a frame kept as it came (``Live.keep``), the values of it that
        clients LISTEN to served at once, the rest taken apart only when asked for; another
        message (a single key's value) at once."""
        out: list[tuple[str, bytes]] = []
        if message.event is not None:
            self._event(message.source.robot, message.source.name, message.event, out)
        elif message.selected is not None or message.parts is not None:
            self.live.keep(message)
            if self.server.listened:  # (else nothing more to do for this frame)
                listened = self.server.listened
                chosen = [(path, list(values), span_of(source)) for source, values in values_of(message)
                          if (path := "/" + source.key) in listened]
                if chosen:
                    for (path, _, _), served in zip(chosen, self.live.update_all(chosen), strict=True):
                        self._served(path, served, out)
        else:
            source = message.source
            if source.section == "derived" and source.robot not in self._present and source.robot not in self._alone:
                self._info.ask(source.robot)  # (no robot's: a map node's outputs, described by it alone)
            self._value(f"/{source.key}", message.values, span_of(source), out)
        if out:
            if message.event is None:
                self.record_latency(time.time() - message.t)
            self.server.send_osc(out)

    def _event(self, robot: str, kind: str, event: dict[str, Any], out: list[tuple[str, bytes]]) -> None:
        path = f"/{robot}/events/{kind}"
        try:
            learned = self.live.learn_event(robot, kind, event)
        except ValueError as exc:
            self._unfit(exc)
            return
        if learned:  # (a kind its info does not name: motion onsets of a features node)
            log.info("%s: PATH_ADDED %s", self.name, path)
            self.server.announce("PATH_ADDED", path)
            self.server.announce("PATH_CHANGED", f"/{robot}/events")
        self._value(path, event_args(kind, event), "", out)

    def _value(self, path: str, values: Any, span: str, out: list[tuple[str, bytes]]) -> None:
        try:
            served = self.live.update(path, list(values), span)
        except ValueError as exc:
            self._unfit(exc)
            return
        self._served(path, served, out)

    def _served(self, path: str, served: list[Any] | ValueError | None, out: list[tuple[str, bytes]]) -> None:
        """What ``Live.update`` gave for ``path``, as an OSC message in ``out`` if a client listens."""
        if isinstance(served, ValueError):
            self._unfit(served)
            return
        if served is None or path not in self.server.listened:
            return
        try:  # (floats alone, a frame's values: one pack, the same bytes as message's)
            out.append((path, encode.floats(path, served) if all(v.__class__ is float for v in served)
                        else encode.message(path, *served)))
        except encode.EncodeError as exc:
            self._unfit(ValueError(f"{path}: OSC cannot carry it: {exc}"))

    def _unfit(self, exc: ValueError) -> None:
        self.count("unfit")
        self.warn("unfit", f"not served: {exc}")


def _loopback(address: str) -> bool:
    return ipaddress.ip_address(address).is_loopback
