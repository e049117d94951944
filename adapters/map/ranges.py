"""The ranges a map's sources are taken in, as robots' infos give them: a joint's
limits from ``<robot>/info``, a derived value's from ``<robot>/info/derived`` (per
component where it gives a box, as a hand position does).

>>> from sonibus.bus.keys import Key
>>> hand = {"key": "pepper/derived/hand/R", "size": 3, "axes": ["x", "y", "z"],
...         "box": {"min": [-0.3, -0.5, -0.28], "max": [0.3, 0.0, 0.45]}}
>>> ranges = Ranges({"joints": [{"name": "HeadYaw", "min": -2.0, "max": 2.0}], "derived": [hand]})
>>> ranges.of(Key.parse("pepper/joints/HeadYaw"), -1), ranges.of(Key.parse("pepper/derived/hand/R"), 2)
((-2.0, 2.0), (-0.28, 0.45))
>>> component("z", ranges.axes["pepper/derived/hand/R"]), component("", ()), component("1", ())
(2, -1, 1)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from sonibus.bus import keys

MAX_COMPONENTS = 64  # a derived value's numbers (its schema's bound; an info's ``size`` is not trusted further)
NO_COMPONENT = 1 << 30  # an axis a value does not have: past any value's end


class Ranges:
    """A robot's ranges from its info: each joint's ``(min, max)`` by name, each derived
    value's by key (per component where the info gives a box), with its axes' names."""

    def __init__(self, info: dict[str, Any]) -> None:
        self.joints: dict[str, tuple[float, float]] = {}
        for joint in info.get("joints") or ():
            if isinstance(joint, dict) and _numbers(joint.get("min"), joint.get("max")):
                self.joints[str(joint.get("name"))] = (float(joint["min"]), float(joint["max"]))
        self.derived: dict[str, list[tuple[float, float] | None]] = {}
        self.axes: dict[str, list[str]] = {}
        for entry in info.get("derived") or ():
            if not isinstance(entry, dict) or not isinstance(entry.get("key"), str):
                continue
            box, key = entry.get("box"), entry["key"]
            if isinstance(box, dict) and isinstance(box.get("min"), list) and isinstance(box.get("max"), list):
                self.derived[key] = [(float(a), float(b)) if _numbers(a, b) else None
                                     for a, b in zip(box["min"][:MAX_COMPONENTS], box["max"], strict=False)]
            elif _numbers(entry.get("min"), entry.get("max")):
                size = entry.get("size")
                size = min(size, MAX_COMPONENTS) if isinstance(size, int) and size > 0 else 1
                self.derived[key] = [(float(entry["min"]), float(entry["max"]))] * size
            axes = entry.get("axes")
            self.axes[key] = [str(a) for a in axes[:MAX_COMPONENTS]] if isinstance(axes, list) else []

    def of(self, key: keys.Key, component: int) -> tuple[float, float] | None:
        """The range of ``key``'s values (of its ``component``; -1: its only one), None if unknown."""
        if key.section == "joints":
            return self.joints.get(key.name)
        spans = self.derived.get(key.key)
        return spans[max(component, 0)] if spans and max(component, 0) < len(spans) else None


def component(axis: str, axes: Sequence[str]) -> int:
    """Which component of a value an ``axis`` names: -1 for none (a value of one number), an
    index (``2``), a name the value's info lists in ``axes``, else ``x``, ``y``, ``z``;
    ``NO_COMPONENT`` for a name it does not have."""
    if not axis:
        return -1
    if axis.isdigit():
        return int(axis)
    if axis in axes:
        return list(axes).index(axis)
    return ("x", "y", "z").index(axis) if axis in ("x", "y", "z") else NO_COMPONENT


def _numbers(*values: Any) -> bool:
    """Two finite numbers that make a range."""
    return all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values) \
        and values[0] != values[1]
