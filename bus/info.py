"""Asking robots for ``<robot>/info`` without waiting: sinks call ``ask`` from
their hot path as often as they like; at most one query per robot is sent per
``retry_s``, and each answer is handed to ``on_info`` on a Zenoh thread (which
should only store or enqueue it).

One query covers ``<robot>/info/**``: the owner's description, and what
feature processors say on ``<robot>/info/derived`` about the derived keys they
publish. ``on_info`` gets the owner's info with those ``derived`` entries (and
``unavailable`` reasons) added, once the query is over; without an owner's
answer it is not called, unless ``derived_alone`` is set and ``<name>/info/derived`` answered
with ``"alone": true`` (its processor's own name, not a robot's): then ``name`` is a source of
derived values that is no robot (a ``map`` node publishing ``<node>/derived/map/<name>``), and
``on_info`` gets ``alone(derived, unavailable)``: its ``derived`` entries, no joints, and
``DERIVED_ALONE`` set, so a sink describes its values as it would a robot's without knowing
what kind of node it is.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from . import keys, messages
from .node import Bus, Reply

MAX_ROBOTS = 1024  # robots asked about and remembered (their retry time)
DERIVED_ALONE = "derived_alone"  # set in the info of a source of derived values that is no robot
UNANSWERED_RETRY_S = 0.25  # a robot whose info nobody answered is asked again this soon (at most 4 a second)


class InfoRequests:
    """``ask(robot)``; answers arrive as ``on_info(robot, info)``, bad ones as ``on_error(robot, text)``."""

    def __init__(self, bus: Bus, on_info: Callable[[str, dict[str, Any]], None],
                 on_error: Callable[[str, str], None], retry_s: float = 2.0, derived_alone: bool = False) -> None:
        self.bus, self.on_info, self.on_error, self.retry_s = bus, on_info, on_error, retry_s
        self.derived_alone = derived_alone  # a name with info/derived and no owner's info is described by the first
        self._asked: dict[str, float] = {}
        self._misses: dict[str, int] = {}  # robot → queries in a row nobody answered
        # ``ask`` comes from a node's threads, the answers and misses from Zenoh's: a miss counted while
        # ``ask`` made room took a node down ("dictionary changed size during iteration", a fuzz campaign)
        self._lock = threading.Lock()
        self._gate = messages.Gate(bus.limits)

    def ask(self, robot: str) -> None:
        now = time.monotonic()
        with self._lock:
            if now - self._asked.get(robot, -math.inf) < self.retry_s:
                return
            if robot not in self._asked and len(self._asked) >= MAX_ROBOTS:  # names made up must not grow it for ever
                self._asked = {r: at for r, at in self._asked.items() if now - at < self.retry_s}
                self._misses = {r: n for r, n in self._misses.items() if r in self._asked}
                if len(self._asked) >= MAX_ROBOTS:  # (all asked just now: this one waits for room)
                    return
            self._asked[robot] = now
        # (not under the lock: a query that ends at once calls ``_unanswered`` from inside ``ask``)
        merge = _Merge(robot, self._answered, self.on_error, self._gate, self._unanswered, self.derived_alone)
        self.bus.ask(keys.info(robot) + "/**", merge.take, merge.finish, timeout=self.retry_s)

    def keep_asking(self, stopping: threading.Event, robots: Callable[[], Iterable[str]]) -> None:
        """Ask each of ``robots()`` again every half ``retry_s`` until ``stopping`` is set (a
        node's worker: what a robot serves changes, a features node adds derived values)."""
        while not stopping.wait(self.retry_s / 2):
            for robot in robots():
                self.ask(robot)

    def _answered(self, robot: str, info: dict[str, Any]) -> None:
        with self._lock:
            self._misses.pop(robot, None)
        self.on_info(robot, info)

    def _unanswered(self, robot: str) -> None:
        # an owner claims its robot before it serves the info (it is still connecting): asked again after
        # UNANSWERED_RETRY_S, not retry_s (a page showed a robot's frames 2.7 s before its controls), then
        # twice as late each time nobody answers, up to retry_s (a claim nobody stands behind: a made-up
        # robot asked 4 times a second, times a thousand of them, is a flood of queries of our own)
        with self._lock:
            if robot in self._asked:
                misses = self._misses[robot] = self._misses.get(robot, 0) + 1
                wait = min(self.retry_s, UNANSWERED_RETRY_S * 2 ** min(misses - 1, 16))
                self._asked[robot] = min(self._asked[robot], time.monotonic() - self.retry_s + wait)


class _Merge:
    """The replies to one info query, merged when the query ends."""

    def __init__(self, robot: str, on_info: Callable[[str, dict[str, Any]], None],
                 on_error: Callable[[str, str], None], gate: messages.Gate,
                 on_none: Callable[[str], None] = lambda robot: None, derived_alone: bool = False) -> None:
        self.robot, self.on_info, self.on_error, self.gate, self.on_none = robot, on_info, on_error, gate, on_none
        self.derived_alone = derived_alone
        self.main: dict[str, Any] | None = None
        self.answered = False  # by an owner (a bad info too: that one is asked again only after retry_s)
        self.derived: list[dict[str, Any]] = []
        self.unavailable: dict[str, Any] = {}
        self.alone = False  # a processor answered for its own name: no owner's info will come
        self._lock = threading.Lock()

    def take(self, reply: Reply) -> None:
        if reply.payload is None:
            return
        key = reply.key
        # an owner answers on its own key, or (a common Zenoh idiom) on the query's
        main = key in (keys.info(self.robot), keys.info(self.robot) + "/**")
        if not main and key != keys.derived_info(self.robot):
            return
        where = keys.info(self.robot) if main else key
        self.answered |= main
        try:
            message = self.gate.check(keys.Key.parse(where), reply.payload)
        except ValueError as exc:  # messages.BadMessage
            self.on_error(self.robot, f"{where} unusable: {exc}")
            return
        with self._lock:
            if main:
                self.main = message
            else:
                self.derived.extend(message["derived"])
                self.alone |= message.get("alone") is True
                self.unavailable.update(message.get("unavailable", {}))

    def finish(self) -> None:
        with self._lock:
            if self.main is not None:
                info = self._merged()
            elif self.answered:  # (an owner's info the gate refused: said already)
                return
            elif self.derived_alone and self.alone:
                info = alone(self.derived, self.unavailable)
            else:
                self.on_none(self.robot)
                return
        self.on_info(self.robot, info)

    def _merged(self) -> dict[str, Any]:
        """The owner's info with the processors' derived entries and unavailable reasons added."""
        info = dict(self.main)
        if self.derived:
            info["derived"] = [*info.get("derived", ()), *self.derived]
        if self.unavailable:
            info["unavailable"] = {**info.get("unavailable", {}), **self.unavailable}
        return info


def alone(derived: list[dict[str, Any]], unavailable: dict[str, Any]) -> dict[str, Any]:
    """The info of a source of derived values that is no robot: what its ``info/derived`` says.

    >>> alone([{"name": "map/head", "min": 0, "max": 127, "unit": "cc"}], {})
    {'joints': [], 'derived': [{'name': 'map/head', 'min': 0, 'max': 127, 'unit': 'cc'}], 'derived_alone': True}
    """
    info: dict[str, Any] = {"joints": [], "derived": list(derived), DERIVED_ALONE: True}
    if unavailable:
        info["unavailable"] = dict(unavailable)
    return info


def watch_nodes(bus: Bus, on_change: Callable[[str, bool], None]) -> Any:
    """Call ``on_change(node, alive)`` for every node on the bus now and whenever one comes
    or goes (its token ``sonibus/nodes/<host>/<node>``), on a Zenoh thread (store, never
    wait): a source of derived values that is no robot has no claim, and is on the bus while
    its node is. Undeclare what it returns to stop."""
    def changed(key: str, alive: bool) -> None:
        node = key[len(keys.NODES) + 1:].partition("/")[2]
        if node:
            on_change(node, alive)
    return bus.watch_tokens(f"{keys.NODES}/*/*", changed)
