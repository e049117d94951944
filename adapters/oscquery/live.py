"""The namespace as it is now: the robots on the bus with their methods, and the
latest value of each readable one. Written by the adapter's bus threads, read by
the web server's loop; every method holds the lock briefly.

A frame (a robot's joints, its derived values) is kept as it came (``keep``: the
latest of each robot's stream) and taken apart into its methods' values only when
a value is asked for (``node``): a robot at 50 frames/s costs nothing per frame
while nobody asks (issue 35); what clients LISTEN to goes through ``update`` as it
comes.

>>> live = Live()
>>> info = {"joints": [{"name": "HeadYaw", "unit": "rad", "min": -2.0, "max": 2.0}]}
>>> live.set_robot("pepper", info), live.set_robot("pepper", info)
('PATH_ADDED', None)
>>> live.update("/pepper/joints/HeadYaw", [0.5]), live.update("/nao/joints/HeadYaw", [0.5])
([0.5], None)
>>> live.learn_event("pepper", "motion", {"t": 1.0, "kind": "motion", "chain": "RArm", "seq": 7, "state": "onset"})
True
>>> live.node("/pepper/events/motion")["TYPE"], live.update("/pepper/events/motion", ["RArm", 7, "onset"])
('sis', ['RArm', 7, 'onset'])
>>> live.set_robot("pepper", info)  # (the info asked again: what was learned stays)
>>> from sonibus.bus.streams import Selection
>>> from sonibus.bus import codec, framing
>>> payload = codec.encode(framing.frame(2.0, 8, ["HeadYaw"], [0.25]))
>>> frame = Selection(["pepper/joints/*"]).incoming("pepper/frame", payload)
>>> live.keep(frame), live.node("/pepper/joints/HeadYaw")["VALUE"]
(None, [0.25])
>>> live.node("/pepper/joints/HeadYaw")["VALUE"], live.drop_robot("pepper"), live.node("/pepper")
([0.25], True, None)
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from sonibus.adapters.osc import scale

from . import namespace
from .namespace import Node, Tree

if TYPE_CHECKING:
    from sonibus.bus import keys
    from sonibus.bus.streams import Incoming

MAX_LEARNED = 64  # event kinds outside EVENT_ARGS served for one robot


class Live:
    """Robots' methods and current values; ``normalized`` scales joints and derived
    values to 0..1 by the robot's ranges, as the OSC sink does; a kept frame's value
    that does not fit its method's ``TYPE`` goes to ``on_unfit`` when the frame is taken
    apart (and is not served)."""

    def __init__(self, normalized: bool = False, on_unfit: Callable[[ValueError], None] = lambda exc: None) -> None:
        self.normalized, self.on_unfit = normalized, on_unfit
        self._kept: dict[str, Incoming] = {}  # a robot's stream ("pepper/frame", "pepper/derived") → its latest
        self.taken_apart = 0  # kept frames taken apart into values (at most one per question, whatever the rate)
        self._robots: dict[str, dict[str, Node]] = {}
        self._spans: dict[str, dict[str, tuple[float, float]]] = {}
        self._values: dict[str, list[Any]] = {}
        self._seen: dict[str, dict[str, Node]] = {}  # robot → the methods of event kinds learned from it
        self._tree = Tree({})
        self._lock = threading.Lock()

    def set_robot(self, robot: str, info: Mapping[str, Any]) -> str | None:
        """Describe ``robot`` by its info; ``PATH_ADDED`` when it is new, ``PATH_CHANGED``
        when what it serves changed, None if nothing did. Raises what ``robot_methods``
        raises for an info that is not shaped as the schema says."""
        described = namespace.robot_methods(robot, info, self.normalized)
        spans = scale.ranges(info)
        with self._lock:
            self._settle()  # (kept frames taken apart with the ranges they came with)
            methods = {**described, **self._seen.get(robot, {})}
            before = self._robots.get(robot)
            if before == methods:
                return None
            self._robots[robot] = methods
            self._spans[robot] = spans
            self._values = {p: v for p, v in self._values.items() if _robot(p) != robot or p in methods}
            self._rebuild()
        return "PATH_ADDED" if before is None else "PATH_CHANGED"

    def learn_event(self, robot: str, kind: str, event: Mapping[str, Any]) -> bool:
        """Serve ``/<robot>/events/<kind>``, typed by ``event``, if ``robot`` is served and that
        method is not (an event kind outside ``EVENT_ARGS``); whether it is new. ``ValueError``
        past ``MAX_LEARNED`` kinds of one robot."""
        path = f"/{robot}/events/{kind}"
        with self._lock:
            if robot not in self._robots or path in self._robots[robot]:
                return False
            learned = self._seen.setdefault(robot, {})
            if len(learned) >= MAX_LEARNED:
                raise ValueError(f"{path!r}: not served, {robot!r} already sends {MAX_LEARNED} kinds of events "
                                 "that its info does not describe")
            learned[path] = namespace.seen_event(kind, event)
            self._robots[robot] = {**self._robots[robot], path: learned[path]}
            self._rebuild()
        return True

    def drop_robot(self, robot: str) -> bool:
        """Forget ``robot``; whether it was served."""
        with self._lock:
            if self._robots.pop(robot, None) is None:
                return False
            self._spans.pop(robot, None)
            self._seen.pop(robot, None)
            self._kept = {k: m for k, m in self._kept.items() if m.source.robot != robot}
            self._values = {p: v for p, v in self._values.items() if _robot(p) != robot}
            self._rebuild()
        return True

    def _rebuild(self) -> None:  # (under the lock)
        self._tree = Tree({p: m for r in self._robots.values() for p, m in r.items()})

    @property
    def robots(self) -> list[str]:
        with self._lock:
            return sorted(self._robots)

    def update(self, path: str, values: Sequence[Any], span: str = "") -> list[Any] | None:
        """Take the latest ``values`` of readable method ``path`` (scaled by the robot's range
        ``span`` — a joint's name, a derived ``feature/name`` — when normalized); what is now
        served, or None if no such method is served. ``ValueError`` for values that do not
        fit the method's ``TYPE``."""
        with self._lock:
            return self._update(path, values, span)

    def update_all(self, items: Sequence[tuple[str, Sequence[Any], str]]) -> list[list[Any] | ValueError | None]:
        """``update`` of each ``(path, values, span)`` with one hold of the lock (a frame's
        listened values): what each serves now, None, or the ``ValueError`` it raised."""
        out: list[list[Any] | ValueError | None] = []
        with self._lock:
            for path, values, span in items:
                try:
                    out.append(self._update(path, values, span))
                except ValueError as exc:
                    out.append(exc)
        return out

    def keep(self, message: Incoming) -> None:
        """A frame of joints or of derived values (``Incoming.joints``: its samples), kept as it
        came, its values served when asked for (``node``); one of a robot not served is not kept."""
        with self._lock:
            if message.source.robot in self._robots:
                self._kept[message.source.key] = message

    def _settle(self) -> None:  # (under the lock)
        """The kept frames taken apart into their methods' values."""
        kept, self._kept = self._kept, {}
        self.taken_apart += len(kept)
        for message in kept.values():
            for source, values in values_of(message):
                try:
                    self._update(f"/{source.key}", values, span_of(source))
                except ValueError as exc:
                    self.on_unfit(exc)

    def _update(self, path: str, values: Sequence[Any], span: str) -> list[Any] | None:  # (under the lock)
        method = self._tree.methods.get(path)
        if method is None or method["ACCESS"] != namespace.READ:
            return None
        if not namespace.fits(method["TYPE"], values):
            raise ValueError(f"{path!r}: {_shown(values)} does not fit its TYPE {method['TYPE']!r}")
        if self.normalized and span and (bounds := self._spans[_robot(path)].get(span)) is not None:
            values = scale.normalized(values, bounds)
        served = self._values[path] = list(values)
        return served

    def node(self, path: str) -> Node | None:
        """The spec's JSON of ``path`` with the current values; None if there is none."""
        with self._lock:
            self._settle()
            tree, values = self._tree, dict(self._values)
        return tree.node(path, values)

    def __contains__(self, path: str) -> bool:
        with self._lock:
            return path in self._tree


def values_of(message: Incoming) -> Iterator[tuple[keys.Key, tuple[float, ...]]]:
    """A frame's (or a derived frame's) values, each with the key it stands for."""
    if message.parts is not None:
        return ((part.source, part.values) for part in message.parts)
    return zip(message.selected.sources, ((value,) for value in message.values), strict=True)


def span_of(source: keys.Key) -> str:
    """The name of a value's range in its robot's info: a joint's name, a derived ``feature/name``."""
    return source.name if source.section == "joints" else f"{source.feature}/{source.name}"


def _shown(values: Sequence[Any]) -> str:
    text = repr(list(values))
    return text if len(text) <= 80 else text[:77] + "..."


def _robot(path: str) -> str:
    return path.split("/", 2)[1]
