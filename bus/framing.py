"""Framing: a robot's joints (or derived values) of one instant as one message, and that
message split again into the samples of the joints' own keys (for scripts and recordings
that want a key per joint). The gate that checks them is ``messages.Gate``.

>>> frame(1.5, 7, ["HeadYaw"], [0.1])
{'t': 1.5, 'seq': 7, 'names': ['HeadYaw'], 'v': [0.1]}
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .messages import FRAME_FIELDS, MAX_VALUE, BadMessage, number, numbers

__all__ = ["derived_frame", "derived_samples", "frame", "frame_samples", "valid_part"]


def frame(t: float, seq: int, names: Sequence[str], values: Sequence[float],
          extra: dict[str, Sequence[float]] | None = None) -> dict[str, Any]:
    """A frame message (``<robot>/frame``): ``values`` and each ``extra`` quantity in the order of ``names``."""
    return {"t": t, "seq": seq, "names": list(names), "v": list(values),
            **{quantity: list(v) for quantity, v in (extra or {}).items()}}


def valid_part(message: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """A frame without the joints whose value (or extra quantity) the gate would
    refuse, and the names left out: what a robot owner publishes when a sensor
    glitches.

    >>> valid_part(frame(1.0, 0, ["HeadYaw", "LHand"], [float("nan"), 0.5]))
    ({'t': 1.0, 'seq': 0, 'names': ['LHand'], 'v': [0.5]}, ['HeadYaw'])
    """
    columns = [message["v"], *(v for q, v in message.items() if q not in FRAME_FIELDS)]
    try:
        for column in columns:
            numbers(column, "v")
        return message, []
    except BadMessage:
        pass
    keep = {i for i in range(len(message["names"]))
            if all(number(c[i]) and -MAX_VALUE <= c[i] <= MAX_VALUE for c in columns)}
    kept = {q: [x for i, x in enumerate(v) if i in keep] if q not in ("t", "seq") else v for q, v in message.items()}
    return kept, [n for i, n in enumerate(message["names"]) if i not in keep]


def frame_samples(message: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """Each joint of a (checked) frame with the sample its own key carries (``t``,
    ``seq``, ``v`` and its extra quantities).

    >>> frame_samples(frame(1.5, 7, ["HeadYaw", "HeadPitch"], [0.1, 0.2], {"cmd": [0.0, 0.3]}))[1]
    ('HeadPitch', {'t': 1.5, 'seq': 7, 'v': 0.2, 'cmd': 0.3})
    """
    t, seq = message["t"], message["seq"]
    extra = {quantity: v for quantity, v in message.items() if quantity not in FRAME_FIELDS}
    return [(name, {"t": t, "seq": seq, "v": value, **{q: v[i] for q, v in extra.items()}})
            for i, (name, value) in enumerate(zip(message["names"], message["v"], strict=True))]


def derived_frame(t: float, seq: int, names: Sequence[str], values: Sequence[Any]) -> dict[str, Any]:
    """A derived frame (``<robot>/derived``): ``values`` (a number or a list of numbers each)
    in the order of ``names`` (``<feature>/<name>``, their keys below ``<robot>/derived/``)."""
    return {"t": t, "seq": seq, "names": list(names), "v": list(values)}


def derived_samples(message: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """Each value of a (checked) derived frame with the sample its own key carries
    (``<feature>/<name>``, ``{t, seq, v}``): what a processor with per-key publishing puts.

    >>> derived_samples(derived_frame(1.5, 7, ["qom/all", "hand/R"], [0.2, [0.1, 0.0, 0.3]]))[1]
    ('hand/R', {'t': 1.5, 'seq': 7, 'v': [0.1, 0.0, 0.3]})
    """
    t, seq = message["t"], message["seq"]
    return [(name, {"t": t, "seq": seq, "v": value})
            for name, value in zip(message["names"], message["v"], strict=True)]
