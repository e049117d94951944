"""Presence on the bus, from liveliness: knowing when a robot leaves or comes
back, and saying so when a robot is there but nothing of it arrives.

A robot's owner holds a token under ``sonibus/robots/<robot>/`` for as long as it
runs (``bus/ownership.py``); Zenoh withdraws it when the process ends or its link
is lost for longer than the transport lease, so watchers learn of a loss within
that time. A robot is on the bus while any claim of it is.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

import zenoh

from . import codec, keys
from .node import Bus
from .ownership import MAX_RIVALS, MAX_ROBOTS, Claim
from .queue import SampleQueue
from .text import printable

log = logging.getLogger(__name__)

SILENCE_S = 3.0  # a robot on the bus whose frames do not arrive for this long is worth a warning
PROBES_PER_ROUND = 8  # silent robots whose owner is asked whether it is up, per half second (claims can be made up)


def watch_robots(bus: Bus, on_change: Callable[[str, bool], None],
                 capped: Callable[[str], None] | None = None) -> zenoh.Subscriber:
    """Call ``on_change(robot, alive)`` (on a Zenoh thread) for every robot already
    on the bus and whenever one leaves or comes back (its first claim appears, its
    last one goes). Claims whose time makes no sense are no robot (``Claim.refusal``);
    at most ``MAX_ROBOTS`` robots of ``MAX_RIVALS`` claims each are followed, a claim
    past that told to ``capped`` (a line saying so) and left out."""
    held: dict[str, set[str]] = {}
    lock = threading.Lock()

    def changed(key: str, alive: bool) -> None:
        claim = Claim.credible(key, bus.limits.max_future_s) if alive else Claim.parse(key)
        if claim is None:
            return
        with lock:
            claims = held.get(claim.robot)
            full = alive and (len(held) >= MAX_ROBOTS if claims is None else len(claims) >= MAX_RIVALS)
            if claims is None and not full:
                claims = held[claim.robot] = set()
            before = bool(claims)
            if claims is not None and not full:
                if alive:
                    claims.add(claim.key)
                else:
                    claims.discard(claim.key)
                    if not claims:
                        del held[claim.robot]
            after = bool(claims)
        if full:
            (capped or _said)(f"robot '{printable(claim.robot)}' (claim of node '{printable(claim.node)}' on "
                   f"'{printable(claim.host)}') not followed: already {MAX_ROBOTS} robots, or {MAX_RIVALS} claims "
                   "of it")
        elif before != after:
            on_change(claim.robot, after)

    return bus.watch_tokens(keys.robot_token(), changed)


_last_said = [-1e18]


def _said(what: str) -> None:
    """A line for a caller that has no node of its own to count with: at most one every 10 s."""
    now = time.monotonic()
    if now - _last_said[0] >= 10.0:
        _last_said[0] = now
        log.warning("%s", what)


class Presence:
    """What ``connection_events`` declares, undeclared by a sink's ``stop``. The sink
    tells it of each robot's data that passed its gate (``heard_from``) and runs
    ``watch`` on a worker of its own (``Adapter.spawn``)."""

    def __init__(self, bus: Bus, queue: SampleQueue, patterns: Sequence[str],
                 capped: Callable[[str], None] | None = None) -> None:
        self.bus, self.queue = bus, queue
        self.wanted = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]
        self.frames = sorted({frame for p in patterns if (frame := _frame_key(p))})
        self.on_bus: dict[str, float] = {}   # robot → since when (monotonic)
        self.heard: dict[str, float] = {}    # robot on the bus → its last data (monotonic)
        self.warned: set[str] = set()
        self._lock = threading.Lock()
        self._entities = [watch_robots(bus, self._changed, capped)]

    def _changed(self, robot: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self.on_bus[robot] = time.monotonic()
            else:
                self.on_bus.pop(robot, None)
                self.heard.pop(robot, None)
                self.warned.discard(robot)
        if any(w.intersects(zenoh.KeyExpr(keys.event(robot, "connection"))) for w in self.wanted):
            event = {"t": time.time(), "kind": "connection", "state": "connected" if alive else "lost",
                     "source": "presence"}
            self.queue.put((keys.event(robot, "connection"), codec.encode(event)))

    def heard_from(self, robot: str) -> None:
        """A frame or joint sample of ``robot`` passed the sink's gate."""
        with self._lock:
            if robot not in self.on_bus:  # (only robots on the bus are remembered: names can be made up)
                return
            self.heard[robot] = time.monotonic()
            told = robot in self.warned
            self.warned.discard(robot)
        if told:
            log.warning("%s: robot '%s': its data arrives now", self.bus.node, robot)

    def silent(self, now: float | None = None) -> list[str]:
        """Robots on the bus, selected by the patterns, of which no frame arrived for ``SILENCE_S``."""
        now = time.monotonic() if now is None else now
        with self._lock:
            on_bus, heard = dict(self.on_bus), dict(self.heard)
        return sorted(robot for robot, since in on_bus.items()
                      if now - max(since, heard.get(robot, since)) >= SILENCE_S
                      and any(zenoh.KeyExpr(f).intersects(zenoh.KeyExpr(keys.frame(robot))) for f in self.frames))

    def watch(self, stopping: threading.Event) -> None:
        """Warn once of each robot that is silent (``silence_hint``) until ``stopping`` is set."""
        if not self.frames:
            return
        probed: dict[str, float] = {}  # robot → when its owner was last asked (the longest unasked go first)
        while not stopping.wait(0.5):
            silent = self.silent()
            with self._lock:
                waiting = [r for r in silent if r not in self.warned]
                probed = {r: at for r, at in probed.items() if r in self.on_bus}
            for robot in sorted(waiting, key=lambda r: probed.get(r, -1.0))[:PROBES_PER_ROUND]:
                probed[robot] = time.monotonic()
                if not self._serving(robot):  # its owner is still connecting to the robot (NAOqi can take a while)
                    continue
                with self._lock:
                    self.warned.add(robot)
                log.warning(silence_hint(self.bus.node, robot))

    def _serving(self, robot: str) -> bool:
        """Whether ``robot``'s owner is up: it serves ``<robot>/info`` once it publishes."""
        try:
            return bool(self.bus.query(keys.info(robot), timeout=1.0))
        except Exception as exc:  # a closing session
            log.debug("%s: info of %s: %s", self.bus.node, robot, exc)
            return False

    def undeclare(self) -> None:
        for entity in self._entities:
            try:
                entity.undeclare()
            except Exception as exc:  # a session closed underneath
                log.debug("undeclare %r: %s", entity, exc)


def silence_hint(node: str, robot: str) -> str:
    """One line: a robot is on the bus but its data does not arrive — the likely causes, in order."""
    return (f"{node}: robot '{robot}' is on the bus but none of its data arrived in {SILENCE_S:g} s — likely, in "
            f"order: (1) access control on the robot's machine refuses this machine's user the keys "
            f"'{robot}/frame' or '{robot}/joints/*' (check its access_control rules and this machine's user; "
            f"`sonibus echo '{robot}/frame' --count 1` here shows whether anything passes); (2) another "
            f"namespace: both machines' [bus] namespace must be the same (`sonibus nodes` on each lists the "
            f"same nodes); (3) a script that puts joint keys only, no frames: set per_joint_keys = true in "
            f"this sink's table (`sonibus echo '{robot}/joints/*' --count 1` shows them)")


def _frame_key(pattern: str) -> str:
    """The frame key expression of the robots whose joints ``pattern`` selects ("" if none)."""
    expr = keys.expr(pattern)
    robot = expr.split("/")[0]
    robot = "*" if robot == "**" else robot
    selected = zenoh.KeyExpr(expr)
    if selected.intersects(zenoh.KeyExpr(keys.joints(robot))) or selected.intersects(zenoh.KeyExpr(keys.frame(robot))):
        return keys.frame(robot)
    return ""


def connection_events(bus: Bus, queue: SampleQueue, patterns: Sequence[str],
                      capped: Callable[[str], None] | None = None) -> Presence:
    """Feed ``queue`` (a sink's) a ``connection`` event, as if the robot's owner had
    sent it, when a robot leaves (``lost``) or comes back (``connected``) — for the
    robots whose events ``patterns`` select. A sink then reacts to a vanished robot
    the same way whatever the cause (a killed process, a cut link, a robot's fall).
    It also warns once (``silence_hint``) when a robot whose joints ``patterns``
    select is on the bus and its owner up (it answers ``<robot>/info``) but none of
    its data reaches the sink for ``SILENCE_S``: the sink calls ``heard_from`` for
    what passes its gate and spawns ``watch``. A robot past ``MAX_ROBOTS`` is not
    followed, and told to ``capped`` (a sink's ``Adapter.capped``)."""
    return Presence(bus, queue, patterns, capped)
