"""Payload codec: msgpack maps, Zenoh encoding ``application/msgpack``."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import msgpack
import zenoh

from .keys import NOT_IN_NAMES, Key

ENCODING = zenoh.Encoding("application/msgpack")


class DecodeError(ValueError):
    """A payload is not a msgpack map."""


def encode(message: dict[str, Any]) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


def decode(payload: bytes | zenoh.ZBytes | None) -> dict[str, Any]:
    if payload is None:
        return {}
    data = payload.to_bytes() if isinstance(payload, zenoh.ZBytes) else payload
    if not data:
        return {}
    try:
        message = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        raise DecodeError(f"payload is not msgpack ({type(exc).__name__}: {exc})") from exc
    if not isinstance(message, dict):
        raise DecodeError(f"payload is a msgpack {type(message).__name__}, expected a map")
    return message


def sample_values(message: dict[str, Any]) -> tuple[float, int, tuple[float, ...]]:
    """``t``, ``seq`` and the values (one float or more) of a joint or derived sample;
    ``KeyError``, ``TypeError`` or ``ValueError`` saying what is wrong."""
    t, seq = stamp(message)
    value = message["v"]
    values = (value,) if number(value) else tuple(value) if isinstance(value, list | tuple) else ()
    if not values or not all(number(v) for v in values):
        raise ValueError(f"v = {value!r} is not a number or a non-empty list of numbers")
    return t, seq, tuple(float(v) for v in values)


def stamp(message: dict[str, Any]) -> tuple[float, int]:
    """``t`` and ``seq`` of a sample or frame; ``KeyError``, ``TypeError`` or ``ValueError`` otherwise."""
    t, seq = message["t"], message["seq"]
    if not number(t) or not math.isfinite(t):
        raise ValueError(f"t = {t!r} is not a finite time")
    if not isinstance(seq, int) or isinstance(seq, bool):
        raise TypeError(f"seq = {seq!r} is not an integer")
    return float(t), seq


def frame(t: float, seq: int, names: Sequence[str], values: Sequence[float],
          extra: dict[str, Sequence[float]] | None = None) -> dict[str, Any]:
    """A frame message (``<robot>/frame``): ``values`` and each ``extra`` quantity in the order of ``names``."""
    return {"t": t, "seq": seq, "names": list(names), "v": list(values),
            **{quantity: list(v) for quantity, v in (extra or {}).items()}}


def frame_joints(message: dict[str, Any]) -> tuple[list[str], list[float]]:
    """The joint names and positions of a frame (``names`` and ``v``, the same length)."""
    names, values = message["names"], message["v"]
    if not isinstance(names, list) or not isinstance(values, list) or len(names) != len(values):
        raise ValueError("names and v are not two lists of the same length")
    for name, value in zip(names, values, strict=True):
        if name.__class__ is not str or name not in _JOINT_NAMES:
            _check_joint_name(name)
        if value.__class__ is not float and not number(value):
            raise ValueError(f"v = {values!r} are not all numbers")
    return names, values


_JOINT_NAMES: set[str] = set()  # names checked already: a frame's names are the same every frame


def _check_joint_name(name: Any) -> None:
    if not isinstance(name, str) or not name or any(c in name for c in NOT_IN_NAMES):
        raise ValueError(f"joint name {name!r} is not one plain key chunk (no '/', wildcards or spaces)")
    if len(_JOINT_NAMES) > 10_000:  # names made up on the fly must not grow it for ever
        _JOINT_NAMES.clear()
    _JOINT_NAMES.add(name)


FRAME_FIELDS = ("t", "seq", "names", "v")  # a frame's own fields; every other one is a quantity per joint


def frame_samples(message: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """Each joint of a frame with the sample its own key carries (``t``, ``seq``, ``v``
    and its extra quantities); raises one of ``BAD``, saying what is wrong.

    >>> frame_samples(frame(1.5, 7, ["HeadYaw", "HeadPitch"], [0.1, 0.2], {"cmd": [0.0, 0.3]}))[1]
    ('HeadPitch', {'t': 1.5, 'seq': 7, 'v': 0.2, 'cmd': 0.3})
    """
    stamp(message)  # checked; the samples keep t and seq as sent
    names, values = frame_joints(message)
    extra = {quantity: v for quantity, v in message.items() if quantity not in FRAME_FIELDS}
    for quantity, v in extra.items():
        if not isinstance(v, list) or len(v) != len(names) or not all(number(x) for x in v):
            raise ValueError(f"{quantity} is not a list of {len(names)} numbers")
    t, seq = message["t"], message["seq"]
    return [(name, {"t": t, "seq": seq, "v": value, **{q: v[i] for q, v in extra.items()}})
            for i, (name, value) in enumerate(zip(names, values, strict=True))]


class Incoming(NamedTuple):
    """A message as a sink takes it: an event (``event`` set), a sample (``t``,
    ``seq``, ``values``) or a frame (``t``, ``seq`` and its joint ``samples``)."""

    source: Key
    event: dict[str, Any] | None = None
    t: float = 0.0
    seq: int = 0
    values: tuple[float, ...] = ()
    samples: tuple[Incoming, ...] = ()

    @property
    def joints(self) -> tuple[Incoming, ...]:
        """The samples it carries: a frame's, or itself."""
        return self.samples if self.source.section == "frame" else (self,)


BAD = (DecodeError, KeyError, TypeError, ValueError)  # what ``incoming`` raises for a bad message


def incoming(key: str, payload: bytes, parsed: dict[str, Key],
             accepts: Callable[[str], bool] = lambda key: True) -> Incoming:
    """Decode what a sink received on ``key``; ``parsed`` caches the keys taken apart;
    a frame keeps the joints ``accepts`` (see ``streams.Streams``).
    Raises one of ``BAD``, saying what is wrong."""
    source = parsed.get(key)
    if source is None:
        source = parsed[key] = Key.parse(key)
    message = decode(payload)
    if source.section == "events":
        return Incoming(source, message)
    if source.section == "frame":
        t, seq = stamp(message)
        samples = []
        prefix = f"{source.robot}/joints/"
        for name, value in zip(*frame_joints(message), strict=True):
            joint = prefix + name
            if accepts(joint):
                parsed_joint = parsed.get(joint) or parsed.setdefault(joint, Key.parse(joint))
                samples.append(Incoming(parsed_joint, None, t, seq, (float(value),)))
        return Incoming(source, None, t, seq, (), tuple(samples))
    return Incoming(source, None, *sample_values(message))


def number(value: Any) -> bool:
    """A real number (``bool`` is an ``int`` in Python, but not a number here)."""
    return isinstance(value, int | float) and not isinstance(value, bool)
