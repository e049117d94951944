"""What a sink subscribes to for the keys it asks for.

A robot owner publishes each frame twice: a sample per joint on
``<robot>/joints/<Joint>`` (for anyone) and the whole frame once on
``<robot>/frame``. A sink that asks for joint keys (``*/joints/*``,
``pepper/joints/R*``) is served from the frames of the robots its patterns
name, and lets through the joints the patterns select: one Zenoh sample per
frame reaches its process instead of one per joint (docs/performance.md).
Publishers that put joint keys only (a script of your own) need
``per_joint_keys = true``.

>>> plan(["*/joints/*", "*/events/*"])
Plan(frames=('*/frame',), keys=('*/events/*',), broad=())
>>> plan(["pepper/**"]).broad, plan(["pepper/joints/R*"], per_joint_keys=True).keys
(('pepper/**',), ('pepper/joints/R$*',))
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import zenoh

from . import codec, keys
from .node import Bus
from .queue import SampleQueue

_JOINTS = zenoh.KeyExpr(keys.joints())
MAX_KEYS = 10_000  # keys taken apart and remembered


@dataclass(frozen=True)
class Plan:
    """Key expressions to subscribe to: ``frames`` (frame keys), ``keys`` (as given,
    without frame keys) and ``broad`` (patterns that select joints and more:
    subscribed without their joint and frame keys, which come from ``frames``)."""

    frames: tuple[str, ...] = ()
    keys: tuple[str, ...] = ()
    broad: tuple[str, ...] = ()


def plan(patterns: Iterable[str], per_joint_keys: bool = False) -> Plan:
    """How to subscribe to ``patterns`` (user patterns; see ``keys.expr``)."""
    frames: list[str] = []
    direct: list[str] = []
    broad: list[str] = []
    for pattern in (keys.expr(p) for p in patterns):
        selected = zenoh.KeyExpr(pattern)
        if per_joint_keys or not selected.intersects(_JOINTS):
            direct.append(pattern)  # (subscribed without frame keys: pepper/** would take them twice)
            continue
        robot = pattern.split("/")[0]
        frame = keys.frame("*" if "**" in robot else robot)
        if frame not in frames:
            frames.append(frame)
        if not _JOINTS.includes(selected):  # it selects more than joints
            broad.append(pattern)
    if any(zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)) for a, b in itertools.combinations(frames, 2)):
        frames = [keys.frame()]  # one subscription, or a frame would come twice; accepts() keeps the robots asked
    return Plan(tuple(frames), tuple(direct), tuple(broad))


class Streams:
    """The subscriptions of ``patterns`` into ``queue``; ``accepts(key)`` tells
    whether a joint of a frame is one the patterns select."""

    def __init__(self, bus: Bus, patterns: Iterable[str], queue: SampleQueue, *,
                 per_joint_keys: bool = False, stamped: bool = False) -> None:
        self.plan = plan(patterns := tuple(patterns), per_joint_keys)
        self._selected = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]
        self._accepted: dict[str, bool] = {}
        self._parsed: dict[str, keys.Key] = {}
        self.subscribers = [bus.subscribe(k, queue=queue, stamped=stamped)[0] for k in self.plan.frames]
        self.subscribers += [bus.subscribe(k, queue=queue, stamped=stamped, skip=keys.is_frame)[0]
                             for k in self.plan.keys]
        self.subscribers += [bus.subscribe(k, queue=queue, stamped=stamped, skip=_from_frames)[0]
                             for k in self.plan.broad]

    def incoming(self, key: str, payload: bytes) -> codec.Incoming:
        """Decode what came on ``key`` (``codec.incoming``: a frame keeps the selected joints)."""
        if len(self._parsed) > MAX_KEYS:  # names made up on the fly must not grow these for ever
            self._parsed.clear()
            self._accepted.clear()
        return codec.incoming(key, payload, self._parsed, self.accepts)

    def take(self, key: str, payload: bytes, stats: dict[str, int],
             warn: Callable[[str, str], None]) -> codec.Incoming | None:
        """``incoming``, counted in a sink's ``stats`` (``received``, a frame as its
        samples; ``bad``); a bad message is ``warn``ed about and gives None."""
        try:
            message = self.incoming(key, payload)
        except codec.BAD as exc:
            stats["received"] += 1
            stats["bad"] += 1
            warn("bad", f"message on '{key}' not sent: {type(exc).__name__}: {exc}")
            return None
        stats["received"] += len(message.samples) or 1
        return message

    def accepts(self, key: str) -> bool:
        """Whether joint ``key`` (taken from a frame) is one the patterns select."""
        accepted = self._accepted.get(key)
        if accepted is None:
            accepted = self._accepted[key] = any(p.intersects(key) for p in self._selected)
        return accepted

    def undeclare(self) -> None:
        for subscriber in self.subscribers:
            subscriber.undeclare()
        self.subscribers.clear()


def _from_frames(key: str) -> bool:
    """Joint and frame keys, which a broad pattern's subscription leaves to the frames."""
    return keys.is_frame(key) or (key.count("/") == 2 and key.split("/")[1] == "joints")
