"""The show's browser surface (adapter ``web``): an operator's page with every robot's
live joints, the nodes' health, the event log and the controls, and a kiosk page of a
few big buttons for visitors.

    [nodes.web]
    adapter = "web"
    listen = "127.0.0.1:8080"

Open http://127.0.0.1:8080/ (operator) or /kiosk. Pages are plain files shipped in
``static/``; they talk JSON over a WebSocket (``/ws``, ``/kiosk/ws``). docs/web.md has
the options, the tokens and the protocol.

Modules: ``config`` (options), ``auth`` (tokens), ``protocol`` (messages), ``server``
(routes and clients), ``slider`` (coalesced joint moves), ``kiosk`` (the buttons' states),
``activity`` (what each robot runs and says, for the page's summary lines), ``maps`` (the
mappings panel: the map nodes' maps, live, and the page's edits carried to them).
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from sonibus.bus import commands, connection, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.claimwatch import owners
from sonibus.bus.errors import ConfigError
from sonibus.bus.info import InfoRequests
from sonibus.bus.messages import Gate
from sonibus.bus.monitor import LOSSES
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams
from sonibus.bus.text import printable
from sonibus.bus.web import WebServer

from . import activity, auth
from .config import WebConfig
from .maps import MapsPanel
from .server import Pages

__all__ = ["WebConfig", "WebPages"]

log = logging.getLogger(__name__)

VERBS = tuple(commands.verbs())  # what an owner that does not say its verbs carries out
MAX_WHY = 240        # characters of why a robot's controller is not matched, as the page shows it
INFO_EVERY_S = 2.0   # how often each robot's info is asked again (behaviors installed, a new owner)
GONE_AFTER_S = 3.0   # a node whose stats have not come for this long is shown gone
FORGET_AFTER_S = 60.0  # ... and left out after this
STATS_EVERY_S = 1.0    # how often the nodes' stats are checked and the pages get them
# Names from the bus the node keeps (made-up ones must not grow it, nor what every page gets each second):
MAX_SHOWN = 32         # robots shown on the operator's page
MAX_NODES = 128        # nodes whose stats are shown
MAX_FIGURES = 32        # counters, and rates, shown of one node (the page shows 6 of them)
MAX_BEHAVIORS = 1000   # behaviors (and postures) of one robot shown


class WebPages(Adapter):
    """Serves the operator's and the kiosk's pages and carries their commands to robots."""

    Config = WebConfig
    counters = ("clients", "commands", "refused", "frames_pushed", "frames_coalesced", "commands_coalesced",
                "commands_dropped", "buttons_timed_out", "capped")

    def _start(self) -> None:
        cfg: WebConfig = self.config
        self._lock = threading.Lock()
        self._present: set[str] = set()           # robots on the bus (all of them: a stop reaches each)
        self._robots: dict[str, dict[str, Any]] = {}  # the shown robots, as the robots message says them
        # robot → its newest frame as it came (key, payload), not yet pushed: checked by the gate when
        # pushed (25 a second), not as it comes (50): most are replaced first (docs/design.md)
        self._latest: dict[str, tuple[str, Any]] = {}
        self._nodes: dict[tuple[str, str], tuple[float, dict[str, Any]]] = {}  # latest stats, when heard
        # each node's newest stats not checked yet: when they came, key, payload, and whether the node is
        # not listed (it takes a place: MAX_NODES counts these, _fresh of them, and the listed)
        self._waiting: dict[tuple[str, str], tuple[float, str, Any, bool]] = {}
        self._fresh = 0
        self._shown = [zenoh.KeyExpr(keys.expr(r)) for r in cfg.robots]
        self.web = WebServer(self, cfg.host, cfg.port, key="listen", limits=cfg.limits, browsers=True,
                             names=auth.names(cfg.token))
        self.pages = Pages(self, self.web, cfg, self._images())
        self._maps = MapsPanel(self, self.pages, self._map_node_listed)  # (before the stats worker tells it)
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: self.warn("info", text),
                                  INFO_EVERY_S)
        self.web.start()
        self.url = self.web.url
        token = "?token=<token>" if cfg.token else ""  # (never the token itself: this line ends up in logs)
        kiosk = "?token=<kiosk_token>" if cfg.kiosk_token else token
        # (the kiosk only when one is configured: its page has no buttons otherwise)
        self.address = f"operator page {self.url}/{token}" + (f", kiosk {self.url}/kiosk{kiosk}" if cfg.kiosk else "")
        log.info("%s: %s", self.name, self.address)
        self._queue = self.own(SampleQueue(cfg.queue))
        patterns = [f"{robot}/joints/*" for robot in cfg.robots] + ["*/events/*"]
        # (frames are kept where they arrive, the newest of each robot for the pages' next tick, which
        # checks it: a thread hand-off a frame less; events come by the queue)
        self._taking = threading.Lock()  # Streams' tables: the feed worker's, or the push tick's
        self._counted = self.stats.counting(self.stats.tally(("received",)))  # (under _taking: no lock of its own)
        self._pushes = self.stats.tally(("frames_coalesced", "frames_pushed"))  # (under _lock)
        self._streams: Streams | None = None
        # (not paced: the newest of a robot's frames is pushed at update_hz, never a burst; docs/design.md)
        self._streams = Streams(self.bus, patterns, self._queue, pace=False, direct=self._direct)
        self.when_stopping(self._queue.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._feed, "feed")
        self.own(self._streams)
        # each node's newest stats wait where they arrive, one a node (a flood of made-up nodes' stats,
        # each up to 64 KiB, holds at most MAX_NODES of them), for the stats worker's check once a second
        # (a wake-up a second, not one a node: issue 35)
        self._gate = Gate(self.bus.limits)
        self.own(self.bus.on_sample(keys.NODE_STATS, self._stats_came, "the nodes' stats"))
        self.spawn(self._take_stats, "stats")
        owners(self.bus)  # (the view of robots' owners a command names, kept from now: the first one too)
        self.own(watch_robots(self.bus, self._robot_changed, self.capped))
        self.web.call(self._push)  # (on the server's loop: no thread of its own, no hand-off to the loop a tick)
        self.spawn(lambda: self._info.keep_asking(self.stopping, self._on_bus), "info")
        self.spawn(self._maps.run, "maps")

    def _images(self) -> dict[str, str]:
        """The kiosk buttons' images by button id, each path from the installation file's folder."""
        images = {}
        for button in self.config.stand.buttons:
            if button.image:
                path = self.resolve(button.image)
                if not Path(path).is_file():
                    where = self.where("kiosk") if self.where else f"node '{self.name}' key 'kiosk'"
                    raise ConfigError(f"{where}: button {button.id!r}: image {path} is not a file (a relative "
                                      "path is taken from the installation file's folder) — give an image file "
                                      "or leave 'image' out")
                images[button.id] = path
        return images

    def metrics(self) -> dict[str, Any]:
        """Pages connected now, and the robots shown."""
        if not hasattr(self, "pages"):
            return {}
        return {"operators": len(self.pages.operators), "kiosks": len(self.pages.kiosks),
                "robots": len(self._robots)}

    def shown_robots(self) -> dict[str, dict[str, Any]]:
        """The robots the operator's pages show now, as the ``robots`` message says them."""
        with self._lock:
            return dict(self._robots)

    def _shows(self, robot: str) -> bool:
        return any(pattern.intersects(zenoh.KeyExpr(robot)) for pattern in self._shown)

    def _on_bus(self) -> list[str]:
        with self._lock:
            return list(self._present)


    # -- robots --------------------------------------------------------------------------

    def _robot_changed(self, robot: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self._present.add(robot)
            else:
                self._present.discard(robot)
                self._latest.pop(robot, None)
            shown = self._robots.get(robot)
            changed = False
            if shown is not None:  # (back: its state as before until its info, asked below, says it anew)
                state = shown["connection"] if alive else {"state": "lost", "error": "its owner left the bus"}
                self._robots[robot] = _with_state(shown if alive else {**shown, "activity": activity.IDLE},
                                                  alive, state)
                changed = self._robots[robot] != shown
            robots = dict(self._robots)
        if changed:
            self.pages.robots(robots)
        if alive:
            self._info.ask(robot)
        else:
            self.pages.robot_left(robot)


    def _take_info(self, robot: str, info: dict[str, Any]) -> None:
        stand = self.config.stand
        if robot == stand.robot:
            missing = [b.id for b in stand.buttons if b.behavior and b.behavior not in info.get("behaviors", ())]
            if missing:  # (said, not refused: a behavior may be installed on the robot later)
                self.warn("kiosk", f"kiosk button(s) {', '.join(missing)}: robot '{robot}' has no such behavior "
                                   f"(its info lists them: `sonibus send {robot} behavior/list`)")
        if not self._shows(robot):
            return
        owner = info.get("owner", {})
        shown = {"owner": f"{owner.get('host', '?')}/{owner.get('node', '?')}", "model": info.get("model", ""),
                 "joints": [{"name": j["name"], "min": j["min"], "max": j["max"], "unit": j.get("unit", "rad"),
                             "chain": j.get("chain", "")} for j in info.get("joints", ())],
                 "verbs": list(info.get("verbs", VERBS))[:64],
                 "behaviors": list(info.get("behaviors", ()))[:MAX_BEHAVIORS],
                 "postures": list(info.get("postures", ()))[:MAX_BEHAVIORS], "rate_hz": info.get("rate_hz"),
                 "awareness": info.get("awareness")}
        controller = info.get("controller")
        if isinstance(controller, dict):  # a ROS 2 robot's trajectory controller: matched or not, and why
            shown["controller"] = {"matched": controller.get("matched") is True,
                                   "why": str(controller.get("why", ""))[:MAX_WHY]}
        state = {k: v for k, v in connection.state_of(info).items() if k in ("state", "error")}
        with self._lock:
            shown["activity"] = self._robots.get(robot, {}).get("activity", activity.IDLE)
            shown = _with_state(shown, robot in self._present, state)
            if self._robots.get(robot) == shown:
                return
            full = robot not in self._robots and len(self._robots) >= MAX_SHOWN
            if not full:
                self._robots[robot] = shown
            robots = dict(self._robots)
        if full:
            self.capped(f"robot '{robot}' not shown: already {MAX_SHOWN} robots on the page")
            return
        self.pages.robots(robots)

    # -- what comes off the bus ---------------------------------------------------------

    def _feed(self) -> None:
        streams = self._streams
        assert streams is not None
        while not self.stopping.is_set():
            item = self._queue.get()  # (woken by an item, or by the queue closed on stop: no poll)
            if item is None:
                continue
            with self._taking:
                message = streams.take(item[0], item[1], self._counted, self.warn)
            if message is not None:
                self._take(message)

    def _direct(self, key: str, payload: Any) -> bool:
        """A robot's frame, on its subscription's callback thread (``Streams``' ``direct``): kept
        as it came as the robot's newest, if the page shows the robot, for the pages' next tick,
        which checks it (``_checked``); one a shown robot (``MAX_SHOWN``), a replaced one counted
        ``frames_coalesced``. Never into the queue (True): nothing here waits on the feed worker."""
        robot = key.partition("/")[0]  # (as keys.Key.parse: a robot is the key's first chunk)
        with self._lock:
            if robot in self._robots:  # (a page shows the frames of the robots it was told of)
                if robot in self._latest:
                    self._pushes["frames_coalesced"] += 1
                self._latest[robot] = (key, payload)
        return True

    def _checked(self, latest: dict[str, tuple[str, Any]]) -> list[tuple[str, dict[str, Any]]]:
        """Each robot and its frame, decoded, of those ``latest`` keeps that the gate lets through (as
        ``Streams.take``: counted ``received``; a bad one refused, counted ``bad`` and warned
        about), on the server's loop: a check is ~20 µs, and ``_taking`` is held by the feed
        worker only while it takes an event."""
        streams = self._streams
        if streams is None:
            return []
        frames = []
        with self._taking:
            for robot, (key, payload) in latest.items():
                message = streams.take(key, payload, self._counted, self.warn)
                if message is not None:
                    frames.append((robot, message.message))
        return frames

    def _take(self, message: Incoming) -> None:
        source = message.source
        if message.event is not None:  # (frames never come by the queue: _direct keeps every one)
            robot, kind = source.robot, source.name
            if kind == "connection":
                self._connection(robot, message.event)
            else:
                self._follow(robot, kind, message.event)
            self.pages.event(robot, kind, message.event, self._shows(robot) or robot == "sonibus")

    def _connection(self, robot: str, event: dict[str, Any]) -> None:
        """A robot's new state, shown at once (its info says it too, but only when asked again)."""
        state = {k: v for k, v in connection.state_of({"connection": event}).items() if k in ("state", "error")}
        with self._lock:
            shown = self._robots.get(robot)
            if shown is None or shown["connection"] == state:
                return
            self._robots[robot] = _with_state(shown, robot in self._present, state)
            robots = dict(self._robots)
        self.pages.robots(robots)

    def _follow(self, robot: str, kind: str, event: dict[str, Any]) -> None:
        """What a shown robot runs and says (its behavior and speech events), whether a stop holds
        it still (its command events), and its awareness as an ``awareness`` command it carried out
        set it (its info says it too, when asked again)."""
        with self._lock:
            shown = self._robots.get(robot)
            if shown is None:
                return
            now = activity.follow(shown["activity"], kind, event)
            changed = shown if now is None else {**shown, "activity": now}
            if kind == "command" and event.get("verb") == "awareness" and event.get("ok") \
                    and shown["awareness"] is not None:
                changed = {**changed, "awareness": bool(event.get("args", {}).get("enabled"))}
            if changed == shown:
                return
            self._robots[robot] = changed
            robots = dict(self._robots)
        self.pages.robots(robots)

    def _stats_came(self, key: str, payload: Any) -> None:
        """A node's stats, on a Zenoh thread: kept as its newest, for the stats worker to check
        (``_take_stats``); left out before they are even checked (a schema check takes ms) when
        its last came less than ``STATS_EVERY_S / 2`` ago (a node says them once a second), or when
        it is not listed while the list is full (``MAX_NODES``: said, counted ``capped``)."""
        node, now = tuple(key.split("/")[2:4]), time.monotonic()
        with self._lock:
            waiting = self._waiting.get(node)
            heard = waiting or self._nodes.get(node)
            full = heard is None and len(self._nodes) + self._fresh >= MAX_NODES
            kept = not full and (heard is None or now - heard[0] >= STATS_EVERY_S / 2)
            if kept:
                fresh = waiting[3] if waiting is not None else node not in self._nodes
                if fresh and waiting is None:
                    self._fresh += 1
                self._waiting[node] = (now, key, payload, fresh)
        if full:
            self.capped(f"the stats on '{printable(key[:140])}' not shown: already {MAX_NODES} nodes listed")
        elif kept:
            self.count("received")

    def _take_stats(self) -> None:
        """Every ``STATS_EVERY_S``: the stats that came since, checked by the gate (a bad one
        counted and warned about), listed, and the list to the pages."""
        while not self.stopping.wait(STATS_EVERY_S):
            with self._lock:
                waiting, self._waiting = self._waiting, {}
            for node, (heard, key, payload, fresh) in waiting.items():
                try:
                    stats = _shown_stats(self._gate.check(keys.Key.parse(key), payload))
                except ValueError as exc:  # messages.BadMessage
                    stats = None
                    self.count("bad")
                    self.warn("bad", f"message on '{printable(key[:140])}' refused: {exc}")
                with self._lock:
                    self._fresh -= fresh  # (its place: listed now, or given back)
                    if stats is not None:
                        self._nodes[node] = (heard, stats)
            self.pages.stats(self._node_stats())
            self._maps.nodes_listed()

    def _map_node_listed(self) -> bool:
        """Whether a map node (adapter ``map``, its stats heard within ``GONE_AFTER_S``) is listed."""
        now = time.monotonic()
        with self._lock:
            return any(stats.get("adapter") == "map" and now - heard <= GONE_AFTER_S
                       for heard, stats in self._nodes.values())

    def _push(self) -> None:
        """On the server's loop: each robot's newest frame to the operators' pages ``update_hz``
        times a second, against deadlines fixed now (skip, never burst: a tick late by more than
        a period skips those it missed, as ``Pacer``). With no operator's page, the ticks stop: an
        operator that comes starts them again (``Pages.on_operator``), its first frames at once
        (the nodes' stats go from their own worker, ``_take_stats``)."""
        loop = asyncio.get_running_loop()
        period, start = 1.0 / self.config.update_hz, loop.time()
        frame = 0
        pending: asyncio.Handle | None = None

        def tick() -> None:
            nonlocal frame, pending
            pending = None
            if self.stopping.is_set() or not self.pages.operators:  # (nobody to show frames to: they
                return                                               # wait, the newest kept)
            with self._lock:
                latest, self._latest = self._latest, {}
            checked = self._checked(latest) if latest else None
            if checked:
                with self._lock:
                    self._pushes["frames_pushed"] += len(checked)
                self.pages.push_frames([_frame(robot, frame) for robot, frame in checked])
            frame += 1
            late = loop.time() - (start + frame * period)
            if late > period:
                frame += int(late / period)
            pending = loop.call_at(start + frame * period, tick)

        def operator_came() -> None:  # (the first page since none: the ticks had stopped)
            nonlocal pending
            if pending is None:
                pending = loop.call_soon(tick)  # (after the page's greeting, sent in the same turn of the loop)

        self.pages.on_operator.append(operator_came)
        tick()

    def _node_stats(self) -> list[dict[str, Any]]:
        now = time.monotonic()
        with self._lock:
            self._nodes = {k: v for k, v in self._nodes.items() if now - v[0] < FORGET_AFTER_S}
            nodes = sorted(self._nodes.items())
        return [{**stats, "gone": now - heard > GONE_AFTER_S} for _, (heard, stats) in nodes]


def _with_state(shown: dict[str, Any], present: bool, state: dict[str, Any]) -> dict[str, Any]:
    """A robot as the ``robots`` message shows it, with its ``connection`` (state, error) and
    ``connected``: on the bus, and connected to its robot."""
    return {**shown, "connection": state, "connected": present and state.get("state") == "connected"}


SHOWN_FIRST = ("received", "sent", *LOSSES)  # the figures a page shows of every node


def _shown_stats(stats: dict[str, Any]) -> dict[str, Any]:
    """What the pages get of a node's stats (checked by the gate): its schema's fields but its
    adapter's own ``metrics``, names cut at 100 characters, at most ``MAX_FIGURES`` counters
    and rates (those the page shows first): a few KB a node, whatever it made up."""
    shown: dict[str, Any] = {k: stats[k] for k in ("t", "uptime_s", "interval_s") if k in stats}
    shown.update({k: stats[k][:100] for k in ("host", "node", "adapter", "state") if k in stats})
    for table in ("counters", "rates"):
        figures = stats.get(table, {})
        first = [k for k in SHOWN_FIRST if k in figures] + [k for k in figures if k not in SHOWN_FIRST]
        shown[table] = {k[:100]: figures[k] for k in first[:MAX_FIGURES]}
    for table, fields in (("latency_ms", ("p50", "p99", "samples")), ("process", ("pid", "cpu_percent",
                                                                                   "rss_bytes", "restarts"))):
        if table in stats:
            shown[table] = {k: stats[table][k] for k in fields if k in stats[table]}
    return shown


def _frame(robot: str, frame: dict[str, Any]) -> str:
    """The ``frame`` message of ``robot``'s frame (checked by the gate: finite numbers)."""
    return json.dumps({"type": "frame", "robot": robot, "t": frame["t"], "seq": frame["seq"], "names": frame["names"],
                       "v": frame["v"]}, allow_nan=False)
