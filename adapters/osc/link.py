"""One target of the OSC sink: its socket, its profile, what it was last sent, and the
datagrams it works out once for a robot's frames and a derived frame's values (its plans)."""

from __future__ import annotations

import math
import socket
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

from sonibus.bus.capped import Capped
from sonibus.bus.keys import Key

from .config import Target
from .profiles import PROFILES, DerivedBytes, FrameBytes

__all__ = ["MAX_PLANS", "MAX_PLAN_BYTES", "Link", "Plan"]

MAX_PLANS = 1024          # plans kept per target (joint lists come from the network)
MAX_PLAN_BYTES = 4 << 20  # and their bytes (a plan holds a datagram's head per joint: 128 long names fill 64 KB)


class Plan(NamedTuple):
    """How one target sends frames of one joint list: their datagrams worked out once,
    and each joint's range (``values = "normalized"``)."""

    datagrams: FrameBytes
    spans: tuple[tuple[float, float] | None, ...] | None


class Link:
    """One target: where it is, its profile, and what it was last sent."""

    def __init__(self, target: Target, destination: tuple[str, int]) -> None:
        self.target = target
        self.profile = PROFILES[target.profile](target)
        self.min_interval = 1.0 / target.max_rate_hz if target.max_rate_hz else 0.0
        self.filtering = target.on_change or target.deadband > 0
        self.framed = target.framed  # (a property of the target's: read once a frame, kept here)
        self.last_values: dict[str, Sequence[float]] = {}
        self.last_sent: dict[str, float] = {}     # slot (key, or robot for frames) → monotonic time
        self.held: dict[str, Any] = {}            # slot → the newest thing waiting for its turn
        self.last_frame_t: dict[str, float] = {}  # robot → t of the last frame sent
        self.sent = 0                             # datagrams sent to it
        # A socket of its own, connected: the kernel keeps the route and the address (cheaper
        # per datagram than sendto: docs/performance.md), and a "port unreachable" from the
        # target's host (nobody listens there) comes back on a later send, where it is counted.
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.socket.connect(destination)
            self.send: Callable[[bytes], int] = self.socket.send
        except OSError:  # (no route yet, say: sendto says so a datagram at a time, and works once there is one)
            self.send = lambda datagram: self.socket.sendto(datagram, destination)
        self.refused_at = 0.0  # when its host last said nothing listens (monotonic; 0: not since it was heard)
        # Frames go out from their precomputed bytes unless a rate cap or a filter needs each value.
        self.direct = not self.min_interval and not self.filtering
        # derived frames' plans, raw values only (a normalized one may wait for its range: the general path);
        # id(Parts.sources) → them and their plan, for the last shape of their values
        self.derived_direct = self.direct and not target.framed and target.values == "raw"
        self.derived_plans: Capped[int, tuple[tuple[Key, ...], DerivedBytes | None]] = Capped(MAX_PLANS,
                                                                                                MAX_PLAN_BYTES)

    def changed(self, key: str, values: Sequence[float]) -> bool:
        """Whether ``values`` pass the on-change/deadband filter (and remember them if so)."""
        if self.filtering:
            last = self.last_values.get(key)
            if last is not None and len(last) == len(values) and all(
                    abs(a - b) <= self.target.deadband for a, b in zip(values, last, strict=True)):
                return False
        self.last_values[key] = values
        return True

    def turn(self, slot: str, now: float) -> bool:
        """Whether ``slot`` may send now under the rate cap."""
        return now - self.last_sent.get(slot, -math.inf) >= self.min_interval
