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
from typing import Any

import zenoh

from . import codec, connection, keys
from .claimwatch import Watching, owners
from .node import Bus
from .queue import SampleQueue

log = logging.getLogger(__name__)

SILENCE_S = 3.0  # a robot on the bus whose frames do not arrive for this long is worth a warning
MAX_REMEMBERED = 1024  # connection states remembered of robots not on the bus (names from events can be made up)
ROUND_S = 0.5  # how often ``watch`` looks while a robot's state is still to be asked (its owner starting)
PROBES_PER_ROUND = 8  # robots whose owner is asked for its state, per half second (claims can be made up)


def watch_robots(bus: Bus, on_change: Callable[[str, bool], None],
                 capped: Callable[[str], None] | None = None) -> Watching:
    """Call ``on_change(robot, alive)`` for every robot already on the bus and whenever
    one leaves or comes back (its first claim appears, its last one goes), from the
    session's one view of the claims (``bus/claimwatch.py``, on its worker: store or
    enqueue, never wait). Claims whose time makes no sense are no robot
    (``Claim.refusal``); at most ``MAX_ROBOTS`` robots of ``MAX_RIVALS`` claims each are
    followed, a claim past that told to ``capped`` (a line saying so) and left out."""
    return owners(bus).watch(bus, on_change, capped or _said)


_last_said = [-1e18]


def _said(what: str) -> None:
    """A line for a caller that has no node of its own to count with: at most one every 10 s."""
    now = time.monotonic()
    if now - _last_said[0] >= 10.0:
        _last_said[0] = now
        log.warning("%s", what)


class Presence:
    """What ``connection_events`` declares, undeclared by a sink's ``stop``. The sink
    tells it of each robot's data that passed its gate (``heard_from``), asks it
    whether an event goes on (``passes``) and runs ``watch`` on a worker of its own
    (``Adapter.spawn``)."""

    def __init__(self, bus: Bus, queue: SampleQueue, patterns: Sequence[str],
                 capped: Callable[[str], None] | None = None) -> None:
        self.bus, self.queue = bus, queue
        self.wanted = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]
        self.frames = sorted({frame for p in patterns if (frame := _frame_key(p))})
        self.on_bus: dict[str, float] = {}   # robot → since when (monotonic)
        self.heard: dict[str, float] = {}    # robot on the bus → its last data (monotonic)
        self.warned: dict[str, str] = {}     # robot → the state its silence was explained with
        self.unsaid: set[str] = set()        # robots on the bus whose state the sink has not been told yet
        self.said: dict[str, tuple[str, float | None]] = {}  # robot → (state, owner's t) of the last connection event
        self.checked: dict[str, float] = {}  # silent robot → when its state was last asked (monotonic)
        self._lock = threading.Lock()
        self._woken = threading.Event()      # a robot came (its state to ask), or the sink stops (``wake``)
        self._entities = [watch_robots(bus, self._changed, capped)]

    def _changed(self, robot: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self.on_bus[robot] = time.monotonic()
                if self._wants_events(robot):
                    self.unsaid.add(robot)  # (its state comes from its info: ``watch``)
                self._woken.set()  # (``watch`` asks its state, or starts its silence's count)
                return
            # a robot the sink was never told of (no state said, no data heard: a made-up claim)
            # leaves without a word: a thousand of them were a thousand events ahead of real frames
            known = robot in self.said or robot in self.heard
            self.on_bus.pop(robot, None)
            self.heard.pop(robot, None)
            self.warned.pop(robot, None)
            self.checked.pop(robot, None)
            self.unsaid.discard(robot)
        if known:
            self._tell(robot, {"t": time.time(), "state": "lost", "source": "presence"})

    def _tell(self, robot: str, fields: dict[str, Any]) -> None:
        """Feed the sink a ``connection`` event of ``robot``, as if its owner had sent it."""
        if self._wants_events(robot):
            self.queue.put((keys.event(robot, "connection"), codec.encode({"kind": "connection", **fields})))

    def _wants_events(self, robot: str) -> bool:
        return any(w.intersects(zenoh.KeyExpr(keys.event(robot, "connection"))) for w in self.wanted)

    def passes(self, robot: str, event: dict[str, Any]) -> bool:
        """Whether ``robot``'s event goes on to the sink's outputs (called by its worker for each):
        a ``connection`` event that repeats the robot's last state, or that its owner said
        before the last one, does not — so a sound tool hears each change once (the owner's
        event and this presence's may both tell it)."""
        if event.get("kind") != "connection":
            return True
        state, source = event.get("state"), event.get("source")
        t = event.get("t") if source != "presence" else None  # (the owner's clock: presence's lost is this one's)
        with self._lock:
            last = self.said.get(robot)
            if last is not None and (state == last[0] or (t is not None and last[1] is not None and t < last[1])):
                return False
            if robot in self.on_bus or len(self.said) < MAX_REMEMBERED:  # (names can be made up: bounded)
                self.said[robot] = (str(state), t)
        return True

    def heard_from(self, robot: str) -> None:
        """A frame or joint sample of ``robot`` passed the sink's gate."""
        with self._lock:
            if robot not in self.on_bus:  # (only robots on the bus are remembered: names can be made up)
                return
            self.heard[robot] = time.monotonic()
            told = self.warned.pop(robot, None) is not None
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
        """Until ``stopping`` is set: tell the sink each robot's connection state as its owner
        says it (its info) once it is on the bus, and warn of each robot that is silent
        (``silence_hint``: once, and again if its state changes while it stays silent). With no
        robot to watch it sleeps with no timeout: its sink calls ``wake`` once ``stopping`` is
        set (``Adapter.when_stopping(presence.wake)``), or its stop waits for it."""
        if not self.frames and not self._wants_events("*"):
            return
        probed: dict[str, float] = {}  # robot → when its owner was last asked (the longest unasked go first)
        while True:
            self._woken.wait(self._next_round())
            self._woken.clear()
            if stopping.is_set():
                return
            now = time.monotonic()
            with self._lock:
                unsaid = list(self.unsaid)
                probed = {r: at for r, at in probed.items() if r in self.on_bus}
            for robot in sorted(unsaid, key=lambda r: probed.get(r, -1.0))[:PROBES_PER_ROUND]:
                probed[robot] = now
                self._say_state(robot)
            silent = [r for r in self.silent(now)  # (warned already: its state is asked again only every SILENCE_S)
                      if not (r in self.warned and now - self.checked.get(r, -SILENCE_S) < SILENCE_S)]
            for robot in sorted(silent, key=lambda r: probed.get(r, -1.0))[:PROBES_PER_ROUND]:
                probed[robot] = now
                self.checked[robot] = now
                connection = self._connection(robot)
                if connection is None:  # its owner does not serve its info (yet): it is still starting
                    continue
                with self._lock:
                    if self.warned.get(robot) == connection["state"] or robot not in self.on_bus:
                        continue
                    self.warned[robot] = connection["state"]
                log.warning(silence_hint(self.bus.node, robot, connection))

    def wake(self) -> None:
        """Wake ``watch`` (on the sink's stop: ``Adapter.when_stopping``; it then looks at ``stopping``)."""
        self._woken.set()

    def _next_round(self) -> float | None:
        """How long ``watch`` sleeps: a round (``ROUND_S``) while a robot's state is still to be
        asked, or a silent robot's owner does not answer yet; otherwise until the soonest robot
        may fall silent (``SILENCE_S`` after its last data), or a warned one is asked again;
        None with no robot to watch (a robot that comes wakes it)."""
        now = time.monotonic()
        with self._lock:
            if self.unsaid:
                return ROUND_S
            due = [max(since, self.heard.get(robot, since)) + SILENCE_S for robot, since in self.on_bus.items()]
        silent = set(self.silent(now))
        if any(robot not in self.warned for robot in silent):
            return ROUND_S
        due = [d for d in due if d > now] + [self.checked.get(r, now) + SILENCE_S for r in silent]
        return max(0.0, min(due) - now) if due else None

    def _say_state(self, robot: str) -> None:
        connection = self._connection(robot)
        if connection is None:  # asked again next time
            return
        with self._lock:
            if robot not in self.unsaid:
                return
            self.unsaid.discard(robot)
        since = connection.get("since")
        t = float(since) if isinstance(since, int | float) and not isinstance(since, bool) else time.time()
        self._tell(robot, {"t": t, "state": connection["state"], "source": "info",
                           **({"error": connection["error"]} if isinstance(connection.get("error"), str) else {})})

    def _connection(self, robot: str) -> dict[str, Any] | None:
        """``robot``'s connection state as its owner says it (``bus/connection.py``); None
        while the owner serves no info."""
        try:
            replies = self.bus.query(keys.info(robot), timeout=1.0)
        except Exception as exc:  # a closing session
            log.debug("%s: info of %s: %s", self.bus.node, robot, exc)
            return None
        info = next((r for r in replies if isinstance(r, dict)), None)
        return connection.state_of(info) if info is not None else None

    def undeclare(self) -> None:
        for entity in self._entities:
            try:
                entity.undeclare()
            except Exception as exc:  # a session closed underneath
                log.debug("undeclare %r: %s", entity, exc)


def silence_hint(node: str, robot: str, state: dict[str, Any] | None = None) -> str:
    """One line: a robot is on the bus but its data does not arrive — the likely causes,
    the robot itself first (its owner's ``state``, ``bus/connection.py``)."""
    state = state or {"state": "connected"}
    if state.get("state") != "connected":
        robot_cause = (f"(1) the robot: its owner says {connection.describe(state)}, so it has nothing to send "
                       f"(`sonibus info {robot}` shows its owner and state; check the robot, its network and the "
                       f"owner's log); if it connects and data still does not come: ")
    else:
        rate = f" and publishes {state['frames_per_s']:.0f} frames/s" if "frames_per_s" in state else ""
        robot_cause = f"(1) not the robot: its owner says it is connected{rate} (`sonibus info {robot}`); so "
    return (f"{node}: robot '{robot}' is on the bus but none of its data arrived in {SILENCE_S:g} s — likely, in "
            f"order: {robot_cause}(2) access control on the robot's machine refuses this machine's user the keys "
            f"'{robot}/frame' or '{robot}/joints/*' (check its access_control rules and this machine's user; "
            f"`sonibus echo '{robot}/frame' --count 1` here shows whether anything passes); (3) another "
            f"namespace: both machines' [bus] namespace must be the same (`sonibus nodes` on each lists the "
            f"same nodes); (4) a script that puts joint keys only, no frames: set per_joint_keys = true in "
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
    sent it, when a robot leaves (``lost``: of a robot the sink was told of, its state or
    its data) or comes back (``connected``) — for the robots whose events ``patterns``
    select. A sink then reacts to a vanished robot the same way whatever the cause (a
    killed process, a cut link, a robot's fall).
    It also warns once (``silence_hint``) when a robot whose joints ``patterns``
    select is on the bus and its owner up (it answers ``<robot>/info``) but none of
    its data reaches the sink for ``SILENCE_S``: the sink calls ``heard_from`` for
    what passes its gate and spawns ``watch``. A robot past ``MAX_ROBOTS`` is not
    followed, and told to ``capped`` (a sink's ``Adapter.capped``)."""
    return Presence(bus, queue, patterns, capped)
