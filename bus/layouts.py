"""Where a derived frame's vectors are, learnt from its key's last frame: what lets the
gate check the usual derived frame's values in C (``Gate.derived_frame``, issue 35).

A features node's derived frame holds numbers and a few vectors (a hand's position), in
the same places every frame. Picking them apart in comprehensions, then checking the
numbers, cost ~25k instructions a frame in every node that takes derived values; here
the types, value by value, are compared with the last frame's in C, and the floats and
the vectors' numbers checked as one vector (``plain_floats``' rule).

>>> layouts = Layouts(max_size=64, max_value=1e6)
>>> layouts.plain("pepper/derived", [0.5, [0.1, 0.2, 0.3]]), layouts.plain("pepper/derived", [0.5, [True]])
(True, False)
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import chain
from math import hypot
from operator import itemgetter
from typing import Any

from .capped import Capped

Picker = Callable[[list[Any]], tuple[Any, ...]]


def _getter(indices: list[int]) -> Picker:
    """What takes the items at ``indices`` out of a list, as a tuple, in C."""
    if len(indices) == 1:
        return lambda values, i=indices[0]: (values[i],)
    return itemgetter(*indices) if indices else lambda values: ()


class Layouts:
    """Per derived frame's key: its last frame's types, what picks its floats and its vectors,
    and their sizes (capped: keys come from the network)."""

    def __init__(self, max_size: int, max_value: float, items: int = 1024, size: int = 2 << 20) -> None:
        self.max_size, self.max_value = max_size, max_value
        self._known: Capped[str, tuple[list[type], Picker, Picker, list[int]]] = Capped(items, size)

    def plain(self, key: str, values: list[Any]) -> bool:
        """Whether a derived frame's ``values`` are floats and vectors of 1..``max_size`` floats,
        their length as one vector within ``max_value``: the usual derived frame. False says
        nothing (the gate then looks at each value, and says which is wrong)."""
        kinds = list(map(type, values))
        layout = self._known.get(key)
        if layout is None or layout[0] != kinds:
            floats = kinds.count(float)
            if floats == len(kinds):
                return hypot(*values) <= self.max_value
            if floats + kinds.count(list) != len(kinds):
                return False
            at = [i for i, kind in enumerate(kinds) if kind is list]
            layout = self._known.put(key, (kinds, _getter([i for i, kind in enumerate(kinds) if kind is float]),
                                           _getter(at), []), 16 * len(kinds) + len(key))
        _, scalars, vectors_of, learnt = layout
        vectors = vectors_of(values)
        sizes = list(map(len, vectors))
        if sizes != learnt:  # (the vectors' sizes: learnt again, within bounds)
            if not (min(sizes) > 0 and max(sizes) <= self.max_size):
                return False
            self._known.put(key, (*layout[:3], sizes), 16 * len(kinds) + len(key))
        flat = list(chain.from_iterable(vectors))
        return list(map(type, flat)).count(float) == len(flat) and hypot(hypot(*scalars(values)), *flat) \
            <= self.max_value
