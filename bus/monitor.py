"""A live model of the show, fed from the bus alone: robots (owner, model, frame
rate, latency, seq gaps, joints), nodes (their stats, and whether their token is
still there) and the last events. ``sonibus top`` draws it; it knows no screen.

It reads only what any machine can: robots' claims and info, ``<robot>/frame``,
``<robot>/events/*``, nodes' tokens, ``sonibus/stats/*/*`` and
``sonibus/events/node``. Zenoh's threads only enqueue or note a token; one
worker of its own takes the messages through the gate (``bus/messages.py``), so
a bad one is counted (``bad``) and named (``problem``), never fatal.
``snapshot()`` is safe from any thread and returns frozen dataclasses.

What it returns (``Snapshot`` and its views) and how an event reads are in
``bus/views.py``.
"""

from __future__ import annotations

import contextlib
import math
import statistics
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from . import codec, connection, keys, messages
from .info import InfoRequests
from .node import Bus, Reply
from .ownership import MAX_RIVALS, Claim
from .queue import SampleQueue
from .stats import Counters
from .text import show_state
from .views import EventView, JointView, NodeView, RobotView, Snapshot, describe_event

WINDOW_S = 1.0          # frame rate and latency are over the last second
HISTORY = 30            # values kept per joint for a sparkline
HISTORY_EVERY_S = 0.1   # at most this often: a sparkline of three seconds
EVENTS = 200            # events kept
LOSSES = ("dropped", "stale", "bad", "errors")  # counters whose moving is a warning
QUEUE = 8192
MAX_SHOWN = 1024        # robots, and nodes, kept: names made up on the fly must not grow it for ever
MAX_WHY = 300          # characters kept of why a node is paused


class _Robot:
    """What the monitor keeps of one robot (under the monitor's lock)."""

    def __init__(self) -> None:
        self.claims: dict[str, Claim] = {}
        self.claimed = False
        self.info: dict[str, Any] | None = None
        self.values: dict[str, float] = {}
        self.history: dict[str, deque[float]] = {}
        self.history_at = -math.inf
        self.recent: deque[tuple[float, float]] = deque()  # (arrival, latency s) over WINDOW_S
        self.seq: int | None = None
        self.gaps = 0
        self.frames = 0
        self.connection: dict[str, Any] | None = None  # its latest state (its info's, then its events')
        self.connection_t = -math.inf                 # when its owner said it (its clock)
        self.show = ""                                # its show's state (``show`` events)


class _Node:
    def __init__(self) -> None:
        self.alive: bool | None = None  # None: its token not seen (yet)
        self.about: dict[str, Any] = {}
        self.stats: dict[str, Any] = {}
        self.stats_at = 0.0
        self.failed = ""
        self.asked = False


class Monitor:
    """The show as the bus tells it; ``start`` subscribes, ``close`` ends it (also as
    a context manager). The ``Bus``'s session stays the caller's."""

    def __init__(self, bus: Bus, events: int = EVENTS, most: int = MAX_SHOWN) -> None:
        self.bus, self.most = bus, most
        self.counters = Counters(("received", "bad", "dropped"))
        self._robots: dict[str, _Robot] = {}
        self._nodes: dict[tuple[str, str], _Node] = {}
        self._events: deque[EventView] = deque(maxlen=events)
        self._problem = ""
        self._lock = threading.Lock()
        self._queue = SampleQueue(QUEUE)
        self.counters.follow("dropped", lambda: self._queue.dropped)
        self._gate = messages.Gate(bus.limits)
        self._entities: list[Any] = []
        self._stopping = threading.Event()
        self._worker: threading.Thread | None = None
        self.failure = ""  # why the monitor's worker died, if it did: its view no longer changes
        self._info = InfoRequests(bus, self._on_info, self._on_bad_info)

    def start(self) -> Monitor:
        if self._worker is not None:
            raise RuntimeError(f"{self!r} is started already")
        for pattern in (keys.frame(), keys.event("*", "*")):
            self._entities.append(self.bus.subscribe(pattern, queue=self._queue)[0])
        self._entities.append(self.bus.subscribe(keys.NODE_STATS, queue=self._queue, skip=self._skip_stats)[0])
        self._entities.append(self.bus.watch_tokens(f"{keys.NODES}/*/*", self._waking(self._node_token)))
        self._entities.append(self.bus.watch_tokens(keys.robot_token(), self._waking(self._robot_token)))
        self._worker = threading.Thread(target=self._work, name="monitor", daemon=True)
        self._worker.start()
        return self

    def close(self) -> None:
        self._stopping.set()
        self._queue.close()
        for entity in reversed(self._entities):
            with contextlib.suppress(Exception):  # a session closed underneath: nothing left to undeclare
                entity.undeclare()
        self._entities.clear()
        if self._worker is not None:
            self._worker.join(2.0)

    def __enter__(self) -> Monitor:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._stopping.is_set() else "watching" if self._worker is not None else "new"
        return f"<Monitor {state} robots={len(self._robots)} nodes={len(self._nodes)} {dict(self.counters)}>"

    def note(self, source: str, kind: str, text: str, alarm: bool = False) -> None:
        """Add an event of the viewer's own (a command's reply) to the list."""
        with self._lock:
            self._listed(EventView(time.time(), source, kind, text, alarm))

    # -- Zenoh's threads: note and return ---------------------------------------------------

    def _node_token(self, key: str, alive: bool) -> None:
        host, _, node = key[len(keys.NODES) + 1:].partition("/")
        with self._lock:
            entry = self._node(host, node)
            if entry is None:
                return
            if entry.alive is not None and entry.alive != alive:  # (not the tokens there when it started)
                self._listed(EventView(time.time(), f"{host}/{node}", "node",
                                              "back on the bus" if alive else "gone: its token vanished", not alive))
            if alive and entry.alive is False:  # a node back under the same name: a new start, asked anew
                entry.about, entry.stats, entry.failed = {}, {}, ""
            entry.alive = alive
            if alive:
                entry.asked = False

    def _robot_token(self, key: str, alive: bool) -> None:
        claim = Claim.parse(key)
        if claim is None:
            return
        why = claim.refusal(self.bus.limits.max_future_s) if alive else ""
        if why:  # (not a robot on the bus: said, and counted as bad input)
            self._refused(f"{key}: {why}")
            return
        with self._lock:
            robot = self._robot(claim.robot)
            if robot is None:
                return
            was = bool(robot.claims)
            if alive and claim.key not in robot.claims and len(robot.claims) >= MAX_RIVALS:
                self.counters.add("bad")
                self._problem = f"{key}: not shown: already {MAX_RIVALS} claims of robot '{claim.robot}'"
                return
            if alive:
                robot.claims[claim.key] = claim
            else:
                robot.claims.pop(claim.key, None)
                if not robot.claims:
                    robot.info = None  # asked again if it comes back: another owner may differ
                    robot.connection, robot.connection_t = None, -math.inf
            if robot.claimed and was != bool(robot.claims):
                text = f"on the bus again, owned by {claim}" if alive else "left the bus: its owner's claim went"
                self._listed(EventView(time.time(), claim.robot, "connection", text, not alive))
            robot.claimed = robot.claimed or alive

    def _skip_stats(self, key: str) -> bool:
        """(On a Zenoh thread.) Stats left out before they are queued and checked (a schema check
        takes ms): a node's that came less than half a second after its last (a node says them
        once a second), or of a node not listed when the list is full."""
        host, _, node = key[len(keys.STATS) + 1:].partition("/")
        with self._lock:
            entry = self._nodes.get((host, node))
            if entry is None and len(self._nodes) >= self.most:
                self.counters.add("bad")
                self._problem = f"node '{node}' on '{host}' not shown: already {self.most} listed"
                return True
        return entry is not None and time.monotonic() - entry.stats_at < 0.5

    def _on_info(self, robot: str, info: dict[str, Any]) -> None:
        # only what a view shows (an info may be 1 MiB of behaviors, times every robot listed)
        kept = {"model": info.get("model", ""),
                "joints": [{k: j[k] for k in ("name", "min", "max", "unit") if k in j} for j in info.get("joints", ())]}
        with self._lock:
            entry = self._robots.get(robot)
            if entry is not None and entry.claims:
                entry.info = kept
                self._connection(entry, connection.state_of(info))

    def _on_bad_info(self, robot: str, reason: str) -> None:
        self._refused(reason)

    def _described(self, host: str, node: str, reply: Reply) -> None:
        """A node's description (``Adapter.describe``; no section of the gate's): what is shown of it, checked here."""
        if reply.payload is None:
            return
        where = keys.node_token(host, node)
        try:
            about = codec.decode(reply.payload)
        except codec.DecodeError as exc:
            self._refused(f"{where}: {exc}")
            return
        if not isinstance(about, dict):
            self._refused(f"{where}: a description is a map, not {type(about).__name__}")
            return
        shown = {k: about[k] for k in ("adapter", "state", "failure") if isinstance(about.get(k), str)}
        since = about.get("since")
        if isinstance(since, (int, float)) and not isinstance(since, bool) and math.isfinite(since):
            shown["since"] = float(since)
        with self._lock:
            if (entry := self._node(host, node)) is not None:
                entry.about = shown

    # -- the worker --------------------------------------------------------------------

    def _work(self) -> None:
        try:
            self._take_all()
        except Exception as exc:  # a bug of the monitor's own: said on every snapshot, not a silent freeze
            self.failure = f"the monitor stopped: {type(exc).__name__}: {exc}"
            raise

    def _waking(self, noted: Callable[[str, bool], None]) -> Callable[[str, bool], None]:
        """``noted``, then the worker woken (``SampleQueue.wake``) when a token came: a node to ask what it
        is, a robot to ask for its info (``_ask``)."""
        def note(key: str, alive: bool) -> None:
            noted(key, alive)
            if alive:
                self._queue.wake()
        return note

    def _wait(self) -> float | None:
        """Until a robot without info is asked again (``InfoRequests`` paces it); otherwise
        until a message or a token comes, or ``close`` closes the queue (None)."""
        with self._lock:
            waiting = any(r.claims and r.info is None for r in self._robots.values())
        return self._info.retry_s if waiting else None

    def _take_all(self) -> None:
        while not self._stopping.is_set():
            for key, payload in self._queue.drain(timeout=self._wait()):
                self.counters.add("received")
                try:
                    self._take(key, payload)
                except ValueError as exc:  # messages.BadMessage, or not a data key
                    self._refused(f"{key}: {exc}")
            self._ask()

    def _take(self, key: str, payload: bytes) -> None:
        parsed = keys.Key.parse(key)
        message = self._gate.check(parsed, payload)
        if parsed.section == "frame":
            self._frame(parsed.robot, message)
        elif parsed.section == "stats":
            host, _, node = parsed.name.partition("/")
            kept = {k: message[k] for k in ("adapter", "state", "uptime_s") if k in message}  # (what a view shows)
            kept["counters"] = {k: message["counters"][k] for k in LOSSES if k in message["counters"]}
            kept["rates"] = {k: message["rates"][k] for k in ("received", "sent", *LOSSES) if k in message["rates"]}
            if isinstance(paused := message.get("metrics", {}).get("paused"), str):  # (why a paused node is)
                kept["metrics"] = {"paused": paused[:MAX_WHY]}
            with self._lock:
                if (entry := self._node(host, node)) is not None:
                    entry.stats, entry.stats_at = kept, time.monotonic()
        elif key == keys.NODE_EVENTS:
            self._node_event(message)
        elif parsed.section == "events":
            self._event(parsed.robot, parsed.name, message)

    def _frame(self, name: str, frame: dict[str, Any]) -> None:
        now, arrival = time.time(), time.monotonic()
        with self._lock:
            robot = self._robot(name)
            if robot is None:
                return
            robot.frames += 1
            seq = frame["seq"]
            if robot.seq is not None and seq > robot.seq + 1:
                robot.gaps += seq - robot.seq - 1
            robot.seq = seq  # (lower: a new owner or a replay that started over, no gap)
            robot.recent.append((arrival, now - frame["t"]))
            _forget(robot.recent, arrival)
            if len(robot.values) > messages.MAX_JOINTS:  # joint names made up on the fly: start over
                robot.values.clear()
                robot.history.clear()
            robot.values.update(zip(frame["names"], map(float, frame["v"]), strict=True))
            if arrival - robot.history_at >= HISTORY_EVERY_S:
                robot.history_at = arrival
                for joint, value in robot.values.items():
                    robot.history.setdefault(joint, deque(maxlen=HISTORY)).append(value)

    def _event(self, robot: str, kind: str, message: dict[str, Any]) -> None:
        alarm = (kind == "conflict" or (kind == "command" and not message.get("ok", True))
                 or message.get("state") in ("failed", "lost", "not_answering"))
        with self._lock:
            self._listed(EventView(float(message["t"]), robot, kind, describe_event(kind, message), alarm))
            if kind == "show" and message.get("state") in ("open", "closed") and robot in self._robots:
                self._robots[robot].show = show_state(str(message["state"]), message.get("next"))
            entry = self._robots.get(robot) if kind == "connection" else None
            if entry is not None and entry.claims:
                self._connection(entry, {**connection.state_of({"connection": message}), "since": message["t"]})

    @staticmethod
    def _connection(robot: _Robot, state: dict[str, Any]) -> None:
        """(Under the lock.) ``robot``'s state, unless its owner said a newer one already."""
        since = state.get("since", -math.inf)
        if since >= robot.connection_t:
            robot.connection, robot.connection_t = state, since

    def _node_event(self, message: dict[str, Any]) -> None:
        host, node = str(message.get("host", "?")), str(message.get("node", "?"))
        with self._lock:
            entry = self._node(host, node)
            if entry is not None and message.get("state") == "failed":
                entry.failed = str(message.get("error", "failed"))
            self._listed(EventView(float(message["t"]), f"{host}/{node}", "node",
                                          describe_event("node", message), message.get("state") == "failed"))

    def _ask(self) -> None:
        """Ask robots on the bus without info for it (``InfoRequests`` paces it), and new nodes what they are."""
        with self._lock:
            robots = [name for name, r in self._robots.items() if r.claims and r.info is None]
            nodes = [hn for hn, n in self._nodes.items() if n.alive and not n.asked]
            for host_node in nodes:
                self._nodes[host_node].asked = True
        for robot in robots:
            self._info.ask(robot)
        for host, node in nodes:
            self.bus.ask(keys.node_token(host, node), lambda r, h=host, n=node: self._described(h, n, r),
                         lambda: None, timeout=2.0)

    def _listed(self, event: EventView) -> None:
        """(Under the lock.) Add ``event``; one like the last (a slider's ``joints/set ok`` 20 times a
        second) counts on the last one instead of pushing the others out."""
        last = self._events[-1] if self._events else None
        if last is not None and (last.source, last.kind, last.text, last.alarm) == \
                (event.source, event.kind, event.text, event.alarm):
            self._events[-1] = replace(event, repeated=last.repeated + 1)
        else:
            self._events.append(event)

    def _robot(self, name: str) -> _Robot | None:
        """(Under the lock.) Robot ``name``'s entry, made if there is room (``most``)."""
        return self._entry(self._robots, name, _Robot, f"robot '{name}'")

    def _node(self, host: str, node: str) -> _Node | None:
        """(Under the lock.) The entry of node ``node`` of ``host``, made if there is room."""
        return self._entry(self._nodes, (host, node), _Node, f"node '{node}' on '{host}'")

    def _entry(self, table: dict[Any, Any], key: Any, make: Callable[[], Any], what: str) -> Any:
        entry = table.get(key)
        if entry is None and len(table) < self.most:
            entry = table[key] = make()
        elif entry is None:
            self.counters.add("bad")
            self._problem = f"{what} not shown: already {self.most} listed"
        return entry

    def _refused(self, reason: str) -> None:
        self.counters.add("bad")
        with self._lock:
            self._problem = reason

    # -- what the show looks like ---------------------------------------------------------

    def snapshot(self) -> Snapshot:
        """The show now: robots and nodes by name, events oldest first."""
        now, arrival = time.time(), time.monotonic()
        with self._lock:
            robots = tuple(_robot_view(name, r, arrival) for name, r in sorted(self._robots.items()))
            nodes = tuple(_node_view(hn, n, arrival) for hn, n in sorted(self._nodes.items()))
            events, problem = tuple(self._events), self._problem
        return Snapshot(now, robots, nodes, events, dict(self.counters), problem, self.failure)


def _forget(recent: deque[tuple[float, float]], now: float) -> None:
    while recent and now - recent[0][0] > WINDOW_S:
        recent.popleft()


def _robot_view(name: str, robot: _Robot, now: float) -> RobotView:
    _forget(robot.recent, now)
    claims = sorted(robot.claims.values(), key=lambda c: c.rank)
    info = robot.info or {}
    limits = {j["name"]: j for j in info.get("joints", ())}
    order = [j for j in limits if j in robot.values] + [j for j in robot.values if j not in limits]
    joints = tuple(JointView(j, robot.values[j], limits.get(j, {}).get("min"), limits.get(j, {}).get("max"),
                             limits.get(j, {}).get("unit", ""), tuple(robot.history.get(j, ())))
                   for j in order)
    latency = statistics.median(lat for _, lat in robot.recent) * 1000.0 if robot.recent else None
    return RobotView(name, f"{claims[0].host}/{claims[0].node}" if claims else "",
                     tuple(f"{c.host}/{c.node}" for c in claims[1:]), str(info.get("model", "")),
                     len(robot.recent) / WINDOW_S, latency, robot.gaps, robot.frames,
                     robot.claimed and not claims, joints, robot.connection or {}, robot.show)


def _node_view(host_node: tuple[str, str], node: _Node, now: float) -> NodeView:
    host, name = host_node
    stats, about = node.stats, node.about
    counters = stats.get("counters", {})
    rates = stats.get("rates", {})
    if node.alive is False:
        state = "gone"
    elif node.failed:
        state = "failed"
    else:
        state = str(stats.get("state") or about.get("state") or "running")
    uptime = None
    if "uptime_s" in stats:
        uptime = stats["uptime_s"] + (now - node.stats_at if node.alive is not False else 0.0)
    elif about.get("since"):
        uptime = max(0.0, time.time() - about["since"])
    # why it is not running: a paused node (a recorder whose disk is full) says it in its latest stats; the
    # description is asked once, so its reason is only for a node that is not running
    why = str(stats.get("metrics", {}).get("paused", "")) if state == "paused" else ""
    return NodeView(host, name, str(stats.get("adapter") or about.get("adapter") or "?"), state, uptime,
                    float(rates.get("received", 0.0)), float(rates.get("sent", 0.0)),
                    {k: int(counters.get(k, 0)) for k in LOSSES},
                    tuple(k for k in LOSSES if rates.get(k, 0) > 0),
                    node.failed or why or (str(about.get("failure", "")) if state != "running" else ""))
