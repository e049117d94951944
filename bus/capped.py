"""Tables keyed by names from the network, bounded by count and by size.

    plans: Capped[str, Plan] = Capped(items=1024, size=4 << 20)
    plan = plans.get(key)
    if plan is None:
        plan = plans.put(key, work_out(key), size=len(key) + 64)  # (starts over past a cap)

What a node works out once per key or joint list (a parsed key, a frame's selection, an
OSC plan) is kept in a table so a robot's next frame finds it. Robots, joints and keys
are named by whoever publishes, so the table has caps; a count alone is not one: one
frame may carry 128 joint names that fill its 64 KB payload, and 1,024 such lists held
107 MB in one sink's selection. ``Capped`` starts over when either cap would be passed,
as the tables did at their count: what live robots use is worked out again at once,
made-up names do not pile up.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

K = TypeVar("K")
V = TypeVar("V")

PER_NAME = 64  # bytes a name costs beside its characters (its str, a slot in a tuple): for ``size_of``


def size_of(names: Iterable[str], per_name: int = PER_NAME) -> int:
    """Bytes (about) that ``names`` hold: their characters and ``per_name`` each."""
    total = 0
    for name in names:
        total += len(name) + per_name
    return total


class Capped(dict[K, V]):
    """A dict of at most ``items`` entries and about ``size`` bytes (as the caller counts
    them in ``put``); read it as a dict, fill it with ``put``."""

    __slots__ = ("held", "items", "size")

    def __init__(self, items: int, size: int) -> None:
        super().__init__()
        self.items, self.size = items, size
        self.held = 0  # bytes put since it was last cleared (a replaced entry still counts: it clears sooner)

    def put(self, key: K, value: V, size: int) -> V:
        """``value`` under ``key``, counted as ``size`` bytes; the table is cleared first if
        it would pass a cap (an entry bigger than ``size`` by itself is not kept)."""
        if size > self.size:
            return value
        if len(self) >= self.items or self.held + size > self.size:
            self.clear()
        self[key] = value
        self.held += size
        return value

    def clear(self) -> None:
        super().clear()
        self.held = 0

    def __repr__(self) -> str:
        return f"<Capped {len(self)}/{self.items} entries, {self.held}/{self.size} bytes>"
