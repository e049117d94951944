"""One watcher of robot claims per session, shared by every node on it.

Every node that follows robots (sinks' presence, the servers, the console, a show, the
owners a command names) reads the claims (``sonibus/robots/<robot>/<since>/<host>/<node>``,
``bus/ownership.py``) from this one view, made on first use (``Bus.shared``): ONE
liveliness subscriber per session, whatever the number of nodes.

Why: ``sonibus run`` holds every node of a machine in one process, on one Zenoh session.
A Python callback handler gets a channel of 256 samples that Zenoh's receiving thread
blocks on when it is full (zenoh-python's default), so a flood of made-up claims (1,200
at once) times one subscriber per node held that thread — and the ``stop`` query behind
the claims on the same link — for 4-10 s (issue 26). Here the subscriber feeds a ring
channel in Rust (``Bus.token_events``): Zenoh never waits for Python; one worker thread
drains it, keeps the table (at most ``MAX_ROBOTS`` robots of ``MAX_RIVALS`` claims, made-up
names must not grow it) and tells the listeners. A listener added late is told every
robot of the table first. Past the ring's capacity the oldest changes are lost: then the
worker reads the claims alive again (a liveliness query) and applies the difference.

Listeners run on that worker: they store or enqueue, never wait (one that blocks holds
every node's view of the robots, never Zenoh).
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from . import keys
from .node import Bus
from .ownership import MAX_RIVALS, MAX_ROBOTS, Claim
from .text import printable

log = logging.getLogger(__name__)

CHANNEL = 4096  # claim changes held for the worker; past that the oldest are dropped and the table re-read
SAY_EVERY_S = 10.0  # the line that says the claims were read again, at most this often
RESYNC_TIMEOUT_S = 2.0  # the liveliness query that re-reads the claims after the channel overflowed
MAX_LEFT_OUT = 16 * MAX_ROBOTS  # claims left out remembered, so a re-read neither counts nor tells them again


@dataclass
class _Listener:
    on_change: Callable[[str, bool], None]
    capped: Callable[[str], None] | None
    guard: Callable[..., Any]  # the listener's node's ``Bus.guarded``: what it raises goes to that node


class Watching:
    """What ``ClaimWatch.watch`` returns: ``undeclare`` stops telling the listener."""

    def __init__(self, watch: ClaimWatch, listener: _Listener) -> None:
        self._watch, self._listener = watch, listener

    def undeclare(self) -> None:
        self._watch._forget(self._listener)


class ClaimWatch:
    """The claims of every robot one session sees (``robots``, ``owner``), and the listeners
    told when a robot comes (its first claim appears) or leaves (its last claim goes)."""

    def __init__(self, bus: Bus, channel: int = CHANNEL) -> None:
        self.bus, self.channel = bus, channel
        self.max_future_s = bus.limits.max_future_s
        self.ignored = 0  # claims left out: no room (``MAX_ROBOTS``, ``MAX_RIVALS``)
        self._left_out: set[str] = set()  # their keys (at most ``MAX_LEFT_OUT``): each counted and told once
        self.resyncs = 0  # times the channel overflowed and the claims were read again
        self._said = -1e18
        self._claims: dict[str, dict[str, Claim]] = {}
        self._listeners: list[_Listener] = []
        self._table = threading.Lock()     # the claims (read by any thread)
        self._telling = threading.Lock()   # one change told to every listener at a time, in order
        self._events = bus.token_events(keys.robot_token(), channel)
        self._worker = threading.Thread(target=self._run, name="claims", daemon=True)
        self._worker.start()
        _WORKERS.add(self._worker)

    # -- what nodes ask -----------------------------------------------------------------

    def robots(self) -> list[str]:
        """The robots with a claim seen now."""
        with self._table:
            return sorted(self._claims)

    def owner(self, robot: str) -> Claim | None:
        """The earliest claim of ``robot`` seen so far (None: none yet)."""
        with self._table:
            held = list(self._claims.get(robot, {}).values())
        return min(held, key=lambda c: c.rank) if held else None

    def watch(self, bus: Bus, on_change: Callable[[str, bool], None],
              capped: Callable[[str], None] | None = None) -> Watching:
        """Call ``on_change(robot, True)`` for every robot on the bus now, then
        ``on_change(robot, alive)`` whenever one comes or leaves, and ``capped(line)`` for a
        claim left out of the full table (on this view's worker; what they raise goes to
        ``bus``'s node)."""
        listener = _Listener(on_change, capped, bus.guarded)
        with self._telling:
            with self._table:
                robots = sorted(self._claims)
                self._listeners.append(listener)
            for robot in robots:
                listener.guard(on_change, f"watcher of {keys.robot_token()}")(robot, True)
        return Watching(self, listener)

    def _forget(self, listener: _Listener) -> None:
        with self._table:
            if listener in self._listeners:
                self._listeners.remove(listener)

    # -- the worker ---------------------------------------------------------------------

    def _run(self) -> None:
        run = 0  # changes taken one after another without the channel running empty
        while True:
            try:
                sample = self._events.try_recv() if run else self._events.recv()
            except Exception as exc:  # the session closed: nothing more comes
                if self.bus.closed:
                    log.debug("claims of %s: %s", self.bus, exc)
                else:  # the view of every node on this session stops here: never silently
                    log.error("claims of %s: the watcher stopped: %s: robots coming and going are no longer "
                              "seen by this process's nodes", self.bus, exc)
                return
            if sample is None:  # the channel ran empty
                if run >= self.channel:  # it was full: changes may have been lost (only then can they be)
                    self._resync()
                run = 0
                continue
            run += 1
            try:
                self._changed(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            except Exception:  # a fault of this view: said, and the next change still told
                log.exception("claims: the change of %s failed", sample.key_expr)

    def _changed(self, key: str, alive: bool) -> None:
        claim = Claim.credible(key, self.max_future_s) if alive else Claim.parse(key)
        if claim is None:
            return
        with self._telling:
            with self._table:
                change = self._apply(claim, alive)
                listeners = list(self._listeners)
            if change == "full":
                line = (f"robot '{printable(claim.robot)}' (claim of node '{printable(claim.node)}' on "
                        f"'{printable(claim.host)}') not followed: already {MAX_ROBOTS} robots, or {MAX_RIVALS} "
                        "claims of it")
                for listener in listeners:
                    if listener.capped is not None:
                        listener.guard(listener.capped, "capped robots")(line)
            elif change:
                for listener in listeners:
                    listener.guard(listener.on_change, f"watcher of {keys.robot_token()}")(claim.robot, alive)

    def _apply(self, claim: Claim, alive: bool) -> str:
        """(Under the table's lock.) ``claim`` added or withdrawn: "robot" when its robot came or
        left with it, "full" when it is left out (no room), "" when no robot changed."""
        held = self._claims.get(claim.robot)
        if not alive:
            if held is None or held.pop(claim.key, None) is None:
                self._left_out.discard(claim.key)
                return ""
            if held:
                return ""
            del self._claims[claim.robot]
            return "robot"
        if held is not None and claim.key in held:
            return ""
        if (held is None and len(self._claims) >= MAX_ROBOTS) or (held is not None and len(held) >= MAX_RIVALS):
            if claim.key in self._left_out:  # (seen again: a re-read after an overflow, or Zenoh twice)
                return ""
            if len(self._left_out) < MAX_LEFT_OUT:
                self._left_out.add(claim.key)
            self.ignored += 1
            return "full"
        self._claims.setdefault(claim.robot, {})[claim.key] = claim
        return "robot" if held is None else ""

    def _resync(self) -> None:
        """After an overflow: the claims alive now, the table brought to them."""
        self.resyncs += 1
        try:
            alive = set(self.bus.alive(keys.robot_token(), timeout=RESYNC_TIMEOUT_S))
        except Exception as exc:  # a closing session
            log.debug("claims: re-reading them: %s", exc)
            return
        if self.resyncs == 1 or time.monotonic() - self._said >= SAY_EVERY_S:  # (a flood: not a line each)
            self._said = time.monotonic()
            log.warning("claims: %d or more changes of robots' claims at once: some may have been lost in the "
                        "channel, read again (%d alive; %d times so far)", self.channel, len(alive), self.resyncs)
        with self._table:
            held = {key for claims in self._claims.values() for key in claims}
        for key in sorted(held - alive):
            self._changed(key, False)
        for key in sorted(alive - held):
            self._changed(key, True)


def owners(bus: Bus) -> ClaimWatch:
    """The ``ClaimWatch`` of ``bus``'s session, made on first use (one per session): what a
    sender needs to name a robot's owner (``owner``) without a query."""
    return bus.shared("claims", ClaimWatch)


# A worker waits inside Zenoh (``recv``); closing its session wakes it. Had the process
# already begun to finalize when it woke, its return into Python would unwind through
# Rust frames and abort the process ("FATAL: exception not rethrown", rc -6: seen at the
# end of ``sonibus top`` and of a ``sonibus run``). So the process lets them return first.
_WORKERS: weakref.WeakSet[threading.Thread] = weakref.WeakSet()
EXIT_WAIT_S = 1.0  # at most, for workers whose session was closed (one left open keeps waiting: not joined)


@atexit.register
def _let_workers_return() -> None:
    deadline = time.monotonic() + EXIT_WAIT_S
    for worker in list(_WORKERS):
        worker.join(max(0.0, deadline - time.monotonic()))
