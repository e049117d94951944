"""``values = "normalized"``: a robot's ranges from its info, and values scaled to 0..1
by them — what the OSC sink sends and what OSCQuery serves.

>>> spans = ranges({"joints": [{"name": "HeadYaw", "min": -2.0, "max": 2.0}],
...                 "derived": [{"name": "hand/L", "min": 0.0, "max": 1.0}]})
>>> spans
{'HeadYaw': (-2.0, 2.0), 'hand/L': (0.0, 1.0)}
>>> normalized([1.0, -3.0], spans["HeadYaw"])
(0.75, 0.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def ranges(info: dict[str, Any]) -> dict[str, tuple[float, float]]:
    """``(min, max)`` of each joint (by name) and derived value (``feature/name``) in a robot's
    info; ``KeyError``/``TypeError``/``ValueError`` when the info is not shaped so."""
    spans = {j["name"]: (float(j["min"]), float(j["max"])) for j in info.get("joints", [])}
    spans.update({d["name"]: (float(d["min"]), float(d["max"])) for d in info.get("derived", [])
                  if "min" in d and "max" in d})
    return spans


def normalized(values: Sequence[float], span: tuple[float, float]) -> tuple[float, ...]:
    """``values`` as fractions of ``span``, clipped to 0..1 (0 for an empty span)."""
    return tuple(fraction(v, span) for v in values)


def fraction(value: float, span: tuple[float, float]) -> float:
    """One value as a fraction of ``span``, clipped to 0..1 (0 for an empty span)."""
    low, high = span
    return min(1.0, max(0.0, (value - low) / (high - low))) if high > low else 0.0
