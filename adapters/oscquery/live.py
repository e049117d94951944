"""The namespace as it is now: the robots on the bus with their methods, and the
latest value of each readable one. Written by the adapter's bus threads, read by
the web server's loop; every method holds the lock briefly.

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
>>> live.node("/pepper/joints/HeadYaw")["VALUE"], live.drop_robot("pepper"), live.node("/pepper")
([0.5], True, None)
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

from sonibus.adapters.osc import scale

from . import namespace
from .namespace import Node, Tree

MAX_LEARNED = 64  # event kinds outside EVENT_ARGS served for one robot


class Live:
    """Robots' methods and current values; ``normalized`` scales joints and derived
    values to 0..1 by the robot's ranges, as the OSC sink does."""

    def __init__(self, normalized: bool = False) -> None:
        self.normalized = normalized
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
            tree, values = self._tree, dict(self._values)
        return tree.node(path, values)

    def __contains__(self, path: str) -> bool:
        with self._lock:
            return path in self._tree


def _shown(values: Sequence[Any]) -> str:
    text = repr(list(values))
    return text if len(text) <= 80 else text[:77] + "..."


def _robot(path: str) -> str:
    return path.split("/", 2)[1]
