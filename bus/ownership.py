"""One owner per robot: the claim, its checks, and the rule that keeps one owner
when two meet (a race, or the halves of a healed network partition).

An owner holds the liveliness token ``sonibus/robots/<robot>/<since>/<host>/<node>``
(``since``: when it claimed, in ms since the epoch), so every node sees who owns
a robot and since when. A node claims a robot only once it is really on the bus
(``session.discover``), refuses to start if it already has an owner, checks again
after declaring its token and watches the robot's claims for the rest of its
life. Of the claims that see each other, the earliest (then host, then node
name) keeps the robot; any other stands by: it publishes nothing, refuses
commands with code ``conflict``, and owns the robot again once the earlier claim
is gone. Both log one line naming the other and tell sinks with a ``conflict``
event (``state`` "standby", ``owner``, ``standby``); a node that owns the robot
again after the owner left says so (``state`` "owner").

>>> Claim.parse("sonibus/robots/pepper/1700000000000/laptop/sim")
Claim(robot='pepper', since_ms=1700000000000, host='laptop', node='sim')
>>> Claim("pepper", 1, "b", "x").rank < Claim("pepper", 2, "a", "x").rank
True
>>> Claim("pepper", 0, "rogue", "x").refusal(max_future_s=5.0)
'claimed at 0 ms since the epoch, before any sonibus bus existed (2025-01-01)'

A claim whose time makes no sense — before ``BUS_EPOCH_MS`` (no sonibus bus existed then:
"claimed at time 0" is made up to win the rule), or further in this machine's future than
the clock-skew tolerance ``[bus] max_future_s`` — is no claim: an owner refuses it in one
line (counted ``claims_refused``) and keeps its robot; commands and views leave it out.
``stop`` runs whatever the claims say: an owner standing by runs it too, and a node that
goes to stand by first stops its robot (``on_standby``).
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from . import keys
from .errors import CommandError, OwnershipError
from .node import Bus
from .publishers import FramePublishers
from .text import printable

log = logging.getLogger(__name__)

CHECK_TIMEOUT_S = 1.0  # a liveliness query for the robot's claims
BUS_EPOCH_MS = 1_735_689_600_000  # 2025-01-01T00:00Z: no sonibus bus existed before; an earlier claim is made up
MAX_RIVALS = 64        # other claims of one robot an owner keeps (the earliest): names made up must not grow it
MAX_ROBOTS = 1024      # robots a session's view of the claims keeps (``bus/claimwatch.py``)
STANDBY_EVENTS_S = 3.0  # after going to stand by, the robot's events still go out this long: the end of what it did
_SINCE = re.compile(r"[0-9]{1,15}")  # ms since the epoch (15 digits: the year 33658), ASCII only


@dataclass(frozen=True)
class Claim:
    """One owner's claim of a robot, as its liveliness token names it."""

    robot: str
    since_ms: int
    host: str
    node: str

    @property
    def key(self) -> str:
        return f"{keys.ROBOTS}/{self.robot}/{self.since_ms}/{self.host}/{self.node}"

    @property
    def rank(self) -> tuple[int, str, str]:
        """The order of the rule: the earliest claim keeps the robot, then host, then node."""
        return (self.since_ms, self.host, self.node)

    @classmethod
    def parse(cls, key: str) -> Claim | None:
        """The claim a token key stands for; None for any other key (a wrong number of
        chunks, a time that is not a plain number, a name that is no plain chunk)."""
        chunks = str(key).split("/")
        if len(chunks) != 6 or "/".join(chunks[:2]) != keys.ROBOTS or not _SINCE.fullmatch(chunks[3]):
            return None
        try:
            for kind, name in (("robot", chunks[2]), ("host", chunks[4]), ("node", chunks[5])):
                keys.check_name(kind, name)
        except ValueError:
            return None
        return cls(chunks[2], int(chunks[3]), chunks[4], chunks[5])

    @classmethod
    def credible(cls, key: str, max_future_s: float) -> Claim | None:
        """The claim of ``key`` if it is one and its time makes sense (see ``refusal``), else None."""
        claim = cls.parse(key)
        return claim if claim is not None and not claim.refusal(max_future_s) else None

    def refusal(self, max_future_s: float, now_ms: int | None = None) -> str:
        """Why this claim's time makes no sense, "" if it does: before ``BUS_EPOCH_MS``, or more
        than ``max_future_s`` ahead of this machine's clock (``now_ms``, default now)."""
        now_ms = time.time_ns() // 1_000_000 if now_ms is None else now_ms
        if self.since_ms < BUS_EPOCH_MS:
            return f"claimed at {self.since_ms} ms since the epoch, before any sonibus bus existed (2025-01-01)"
        ahead = (self.since_ms - now_ms) / 1000
        if ahead > max_future_s:
            return (f"claimed {ahead:,.0f} s ahead of this machine's clock, beyond [bus] max_future_s = "
                    f"{max_future_s:g} s (a clock out of step: NTP on every machine)")
        return ""

    @property
    def address(self) -> str:
        """What a command names to reach this owner alone (``<robot>/cmd/<verb>?owner=<address>``)."""
        return f"{self.since_ms}/{self.host}/{self.node}"

    def who(self) -> dict[str, Any]:
        return {"host": self.host, "node": self.node, "since": self.since_ms / 1000}

    def __str__(self) -> str:
        return f"node '{self.node}' on host '{self.host}'"


def claims(keys_: Iterable[str], max_future_s: float = 5.0) -> dict[str, list[Claim]]:
    """Token keys → each robot's claims, earliest (the owner) first; claims whose time
    makes no sense (``Claim.refusal``) left out."""
    found: dict[str, list[Claim]] = {}
    for key in keys_:
        claim = Claim.credible(key, max_future_s)
        if claim is not None:
            found.setdefault(claim.robot, []).append(claim)
    return {robot: sorted(cs, key=lambda c: c.rank) for robot, cs in sorted(found.items())}


class Ownership:
    """``bus``'s node owning ``robot``: its token, its watch on the robot's other
    claims, and whether it may act (``active``). Made by ``Adapter.claim_robot``;
    ``undeclare`` gives the robot up. Owners publish frames through ``publish_frame``
    (``FramePublishers``: also the per-joint keys while anyone subscribes to them)."""

    def __init__(self, bus: Bus, robot: str, hint: str,
                 on_refused: Callable[[str, str], None] | None = None) -> None:
        self.bus, self.robot, self.hint = bus, robot, hint
        self.claim = Claim(robot, 0, bus.host, bus.node)
        self.active = False
        self.owner: Claim | None = None       # the claim this node stands by for
        self.on_standby: Callable[[], None] | None = None  # called (on a Zenoh thread) when it goes to stand by
        # a claim refused (``key``, why): its owner's node counts and warns; by default a log line
        self.on_refused = on_refused or (lambda key, why: log.warning("%s: %s", self.bus.node, why))
        self._rivals: dict[str, Claim] = {}
        self._gone: set[str] = set()           # claims withdrawn: a query's late answer must not revive one
        self._told: set[str] = set()           # later claims this owner has logged
        self._standby_at = -1e18               # when it last went to stand by (monotonic)
        self._lock = threading.Lock()
        self._entities: list[Any] = []
        self._publishers: FramePublishers | None = None

    # -- claiming -----------------------------------------------------------------

    def take(self) -> None:
        """Claim the robot: ``OwnershipError`` naming the owner if it has one already."""
        pattern = keys.robot_token(self.robot)
        self._entities.append(self.bus.watch_tokens(pattern, self._changed))
        self.bus.discover()
        self._seen(self.bus.alive(pattern, timeout=CHECK_TIMEOUT_S))
        rivals = self._rivals_now()
        if rivals and all(self._earlier_self(c) for c in rivals):
            # This node's previous run, killed: its claim lasts until the transport lease ends.
            deadline = time.monotonic() + self.bus.lease_s + 0.5
            while rivals and time.monotonic() < deadline:
                time.sleep(0.1)
                rivals = self._rivals_now()
        if rivals:
            elsewhere = "" if rivals[0].host == self.bus.host else (
                " — another installation on this network? Keep yours to itself with a namespace of its own "
                "([bus] namespace = \"<yours>\", or --namespace NAME: README \"Installations\")")
            raise OwnershipError(f"robot '{self.robot}' is already owned by {rivals[0]}; {self.hint}{elsewhere}")
        with self._lock:  # (together: a rival's change seen meanwhile must not find a claim yet inactive)
            self.claim = Claim(self.robot, time.time_ns() // 1_000_000, self.bus.host, self.bus.node)
            self.active = True
        self._entities.append(self.bus.token(self.claim.key))
        self._seen(self.bus.alive(pattern, timeout=CHECK_TIMEOUT_S))  # a claim made meanwhile
        with self._lock:
            self._gone.clear()  # (only a query's late answer needed them)
        self._decide()

    def _rivals_now(self) -> list[Claim]:
        with self._lock:
            return sorted(self._rivals.values(), key=lambda c: c.rank)

    def _earlier_self(self, claim: Claim) -> bool:
        return (claim.host, claim.node) == (self.bus.host, self.bus.node)

    def _changed(self, key: str, alive: bool) -> None:
        claim = self._sensible(key) if alive else Claim.parse(key)
        if claim is None or claim == self.claim:
            return
        with self._lock:
            if alive:
                self._add(claim)
                self._gone.discard(claim.key)
            else:
                self._rivals.pop(claim.key, None)
                self._told.discard(claim.key)
                if not self.claim.since_ms:  # (only a query's late answer before the claim needs them)
                    self._gone.add(claim.key)
        if self.claim.since_ms:
            self._decide()

    def _seen(self, found: Iterable[str]) -> None:
        for key in found:
            claim = self._sensible(key)
            with self._lock:
                if claim is not None and claim != self.claim and claim.key not in self._gone:
                    self._add(claim)

    def _sensible(self, key: str) -> Claim | None:
        """The claim of ``key``, or None: refused (``on_refused``) when it is no claim or its
        time makes no sense, so a made-up claim never takes the robot from its owner."""
        claim = Claim.parse(key)
        why = claim.refusal(self.bus.limits.max_future_s) if claim is not None else "not a claim key"
        if claim is not None and claim.robot != self.robot:
            return None
        if why:
            self.on_refused(key, f"robot '{self.robot}': refused the claim {printable(key)[:200]!r}: {why}; "
                                 "it takes nothing from this node")
            return None
        return claim

    def _add(self, claim: Claim) -> None:
        """(Under the lock.) Keep ``claim`` among the rivals: the earliest ``MAX_RIVALS`` of them."""
        if claim.key in self._rivals or len(self._rivals) < MAX_RIVALS:
            self._rivals[claim.key] = claim
            return
        latest = max(self._rivals.values(), key=lambda c: c.rank)
        kept = claim if claim.rank < latest.rank else latest
        dropped = latest if kept is claim else claim
        if kept is claim:
            del self._rivals[latest.key]
            self._told.discard(latest.key)
            self._rivals[claim.key] = claim
        self.on_refused(dropped.key, f"robot '{self.robot}': more than {MAX_RIVALS} claims of it at once; "
                                     f"the latest, {dropped}, is left out")

    def _decide(self) -> None:
        """Apply the rule; log (and tell sinks) what changed."""
        with self._lock:
            rivals = sorted(self._rivals.values(), key=lambda c: c.rank)
            first = rivals[0] if rivals and rivals[0].rank < self.claim.rank else None
            was, self.active, self.owner = self.active, first is None, first
            new = [c for c in rivals if c.rank > self.claim.rank and c.key not in self._told]
            self._told.update(c.key for c in new)
        name = f"{self.bus.node}: robot '{self.robot}'"
        if was and first is not None:
            self._standby_at = time.monotonic()
            log.warning("%s is also owned by %s, which claimed it first: this node stands by (it stops its "
                        "robot, publishes nothing, refuses every command but stop) until that one leaves", name, first)
            self._event("standby", first, self.claim)
            if self.on_standby is not None:
                self.on_standby()
        elif not was and first is None:
            log.warning("%s: its owner left; this node owns it again", name)
            self._event("owner", self.claim)
        if first is None:
            for claim in new:
                log.warning("%s is also claimed by %s, which claimed it later and stands by: this node keeps it",
                            name, claim)
                self._event("standby", self.claim, claim)  # said by both: either may be out of a sink's reach

    def _event(self, state: str, owner: Claim, standby: Claim | None = None) -> None:
        event = {"t": time.time(), "kind": "conflict", "state": state, "owner": owner.who()}
        if standby is not None:
            event["standby"] = standby.who()
        try:
            self.bus.put(keys.event(self.robot, "conflict"), event)
        except Exception as exc:  # a closing session: the log line remains
            log.debug("%s: conflict event not sent: %s", self.bus.node, exc)

    @property
    def speaks(self) -> bool:
        """Whether the robot's events go out: while it owns the robot, and for ``STANDBY_EVENTS_S``
        after it went to stand by (the end of the motion its stop cut short)."""
        return self.active or time.monotonic() - self._standby_at < STANDBY_EVENTS_S

    def check(self, verb: str, addressed: str | None = None) -> None:
        """``CommandError`` (``conflict``) while this node stands by for another owner, or
        when the command is ``addressed`` to another owner (the one its sender sees first:
        while two owners have not yet seen each other, only that one runs it). ``stop``
        always runs: whatever the claims say, a robot must stop when asked."""
        if verb == "stop":
            return
        owner = self.owner
        if not self.active and owner is not None:
            raise CommandError("conflict", f"{verb}: robot '{self.robot}' is owned by {owner}; node "
                                           f"'{self.bus.node}' on host '{self.bus.host}' stands by")
        if addressed and addressed != self.claim.address:
            host, _, node = addressed.partition("/")[2].partition("/")
            raise CommandError("conflict", f"{verb}: sent to node '{node}' on host '{host}' as the owner of robot "
                                           f"'{self.robot}', not to node '{self.bus.node}' on host '{self.bus.host}'")

    # -- an owner's frames ------------------------------------------------------------

    def publish_frame(self, message: dict[str, Any]) -> bool:
        """Put a frame (checked by the caller) through the robot's ``FramePublishers``;
        False (nothing sent) while standing by."""
        if not self.active:
            return False
        if self._publishers is None:
            self.declare_publishers()
        self._publishers.put(message)
        return True

    def publish_values(self, t: float, seq: int, names: Sequence[str], values: Sequence[float]) -> bool:
        """``publish_frame`` of the frame of ``values`` (each a ``float`` within range, no other
        quantity: ``FramePublishers.put_values``), with no map made of it."""
        if not self.active:
            return False
        if self._publishers is None:
            self.declare_publishers()
        self._publishers.put_values(t, seq, names, values)
        return True

    def declare_publishers(self, joints: Iterable[str] = ()) -> None:
        """Declare the robot's frame publisher and those of ``joints`` ahead of the first frame."""
        self._publishers = self._own(FramePublishers(self.bus, self.robot, joints))

    def _own(self, entity: Any) -> Any:
        self._entities.append(entity)
        return entity

    def undeclare(self) -> None:
        """Give the robot up: the token, the watch and the publishers."""
        self.active = False
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except Exception as exc:  # a session closed underneath
                log.debug("undeclare %r: %s", entity, exc)
        self._entities.clear()

    def __repr__(self) -> str:
        return f"<Ownership {self.claim.key} {'active' if self.active else 'standby'}>"
