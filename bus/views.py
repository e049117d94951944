"""What ``bus/monitor.py``'s model of the show hands out: frozen views of its robots,
nodes and events at one instant (``Snapshot``), and an event's short text.

>>> describe_event("behavior", {"t": 0.0, "kind": "behavior", "name": "wave", "state": "started"})
'started wave'
>>> describe_event("command", {"verb": "say", "args": {}, "ok": False, "error": "text is empty"})
'say refused: text is empty'
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["EventView", "JointView", "NodeView", "RobotView", "Snapshot", "describe_event"]


@dataclass(frozen=True)
class JointView:
    """One joint of a robot: its latest value, its limits (from the robot's info) and recent values."""

    name: str
    value: float
    min: float | None = None
    max: float | None = None
    unit: str = ""
    history: tuple[float, ...] = ()

    @property
    def fraction(self) -> float | None:
        """Where the value lies between the limits, 0..1 (None without limits).

        >>> JointView("HeadYaw", 0.5, -1.0, 1.0).fraction
        0.75
        """
        if self.min is None or self.max is None or self.max <= self.min:
            return None
        return min(1.0, max(0.0, (self.value - self.min) / (self.max - self.min)))


@dataclass(frozen=True)
class RobotView:
    """A robot: who owns it (``host/node``; ``standby``: other claims), its model,
    frames over the last second, latency (median of now − ``t``, ms), frames missing
    by ``seq``, whether its owner's token went (``gone``) and its connection state as
    its owner says it (``connection``: state, error..., ``bus/connection.py``)."""

    name: str
    owner: str = ""
    standby: tuple[str, ...] = ()
    model: str = ""
    rate_hz: float = 0.0
    latency_ms: float | None = None
    gaps: int = 0
    frames: int = 0
    gone: bool = False
    joints: tuple[JointView, ...] = ()
    connection: dict[str, Any] = field(default_factory=dict)  # (empty: not known yet)
    show: str = ""  # its show's state and next change, as its ``show`` events say ("": no show heard)

    @property
    def connected(self) -> bool:
        return self.connection.get("state") == "connected"


@dataclass(frozen=True)
class NodeView:
    """A node, from its token, description and stats: rates per second, its loss
    counters (``LOSSES``) and those that moved in its last interval (``moved``);
    ``state`` is ``gone`` once its token vanished (it stays listed)."""

    host: str
    node: str
    adapter: str = "?"
    state: str = "running"
    uptime_s: float | None = None
    rx_per_s: float = 0.0
    tx_per_s: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)
    moved: tuple[str, ...] = ()
    error: str = ""

    @property
    def gone(self) -> bool:
        return self.state == "gone"


@dataclass(frozen=True)
class EventView:
    """An event as shown: when, whose (a robot, or ``host/node``), its kind and a short text."""

    t: float
    source: str
    kind: str
    text: str
    alarm: bool = False  # a failure, a refusal, a conflict
    repeated: int = 1    # the same event in a row this many times (``t``: the last one's)


@dataclass(frozen=True)
class Snapshot:
    """The show at one instant; ``counters``, ``problem`` and ``failure`` are the
    monitor's own (what it received, refused as bad, dropped; the last refusal's
    reason; why it stopped, if it did)."""

    t: float
    robots: tuple[RobotView, ...]
    nodes: tuple[NodeView, ...]
    events: tuple[EventView, ...]
    counters: dict[str, int]
    problem: str = ""
    failure: str = ""


def describe_event(kind: str, message: dict[str, Any]) -> str:
    """A short text of an event's fields (those of its kind first, as the schemas name them)."""
    if kind == "command":  # (its error is the owner's message)
        outcome = "ok" if message.get("ok") else f"refused: {message.get('error', '?')}"
        return f"{message.get('verb', '?')} {outcome}"
    if kind == "node":
        return f"{message.get('adapter', '?')} {message.get('state', '?')}: {message.get('error', '')}".rstrip(": ")
    if kind == "conflict":
        owner = message.get("owner") or {}
        return f"{message.get('state', '?')}, owner {owner.get('node', '?')} on {owner.get('host', '?')}"
    if kind == "speech":
        return f"{message.get('state', '?')} '{message.get('text', '')}'"
    if kind == "connection":  # (its error says why it is not connected)
        error = message.get("error")
        return f"{message.get('state', '?')}: {error}" if error else str(message.get("state", "?"))
    if kind in ("behavior", "posture"):  # (the state first: a long name is what a narrow view cuts)
        return f"{message.get('state', '?')} {message.get('name', '?')}"
    return " ".join(f"{k}={v}" for k, v in message.items() if k not in ("t", "kind"))
