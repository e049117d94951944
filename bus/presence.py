"""Presence on the bus, from liveliness: who owns a robot, and knowing when a
robot leaves or comes back.

A robot's owner holds the token ``sonibus/robots/<robot>`` for as long as it
runs; Zenoh withdraws it when the process ends or its link is lost for longer
than the transport lease, so watchers learn of a loss within that time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import zenoh

from . import codec, keys
from .errors import OwnershipError
from .node import Bus
from .queue import SampleQueue


def claim(bus: Bus, robot: str, hint: str = "stop that node or give this robot another name") -> zenoh.LivelinessToken:
    """The liveliness token that makes ``bus``'s node the owner of ``robot``;
    ``OwnershipError`` naming the owner (and ``hint``) if it is taken."""
    if bus.alive(keys.robot_token(robot)):
        replies = bus.query(keys.info(robot), timeout=1.0)
        owner = replies[0].get("owner", {}) if replies else {}
        who = f"node '{owner.get('node')}' on host '{owner.get('host')}'" if owner else "another node"
        raise OwnershipError(f"robot '{robot}' is already owned by {who}; {hint}")
    return bus.token(keys.robot_token(robot))


def watch_robots(bus: Bus, on_change: Callable[[str, bool], None]) -> zenoh.Subscriber:
    """Call ``on_change(robot, alive)`` (on a Zenoh thread) for every robot already
    on the bus and whenever one leaves or comes back."""
    prefix = len(keys.ROBOTS) + 1

    def changed(sample: zenoh.Sample) -> None:
        on_change(str(sample.key_expr)[prefix:], sample.kind == zenoh.SampleKind.PUT)

    return bus.session.liveliness().declare_subscriber(f"{keys.ROBOTS}/*", changed, history=True)


def connection_events(bus: Bus, queue: SampleQueue, patterns: Sequence[str]) -> zenoh.Subscriber:
    """Feed ``queue`` (a sink's) a ``connection`` event, as if the robot's owner had
    sent it, when a robot leaves (``lost``) or comes back (``connected``) — for the
    robots whose events ``patterns`` select. A sink then reacts to a vanished robot
    the same way whatever the cause (a killed process, a cut link, a robot's fall)."""
    wanted = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]

    def changed(robot: str, alive: bool) -> None:
        if any(w.intersects(zenoh.KeyExpr(keys.event(robot, "connection"))) for w in wanted):
            event = {"t": time.time(), "kind": "connection", "state": "connected" if alive else "lost",
                     "source": "presence"}
            queue.put((keys.event(robot, "connection"), codec.encode(event)))

    return watch_robots(bus, changed)
