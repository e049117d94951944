"""Payload codec: msgpack maps, Zenoh encoding ``application/msgpack``."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import msgpack
import zenoh

from .keys import Key

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
    t, seq, value = message["t"], message["seq"], message["v"]
    if not number(t) or not math.isfinite(t):
        raise ValueError(f"t = {t!r} is not a finite time")
    if not isinstance(seq, int) or isinstance(seq, bool):
        raise TypeError(f"seq = {seq!r} is not an integer")
    values = (value,) if number(value) else tuple(value) if isinstance(value, list | tuple) else ()
    if not values or not all(number(v) for v in values):
        raise ValueError(f"v = {value!r} is not a number or a non-empty list of numbers")
    return float(t), seq, tuple(float(v) for v in values)


class Incoming(NamedTuple):
    """A message as a sink takes it: an event (``event`` set) or a sample (``t``, ``seq``, ``values``)."""

    source: Key
    event: dict[str, Any] | None = None
    t: float = 0.0
    seq: int = 0
    values: tuple[float, ...] = ()


BAD = (DecodeError, KeyError, TypeError, ValueError)  # what ``incoming`` raises for a bad message


def incoming(key: str, payload: bytes, parsed: dict[str, Key]) -> Incoming:
    """Decode what a sink received on ``key``; ``parsed`` caches the keys taken apart.
    Raises one of ``BAD``, saying what is wrong."""
    source = parsed.get(key)
    if source is None:
        source = parsed[key] = Key.parse(key)
    message = decode(payload)
    if source.section == "events":
        return Incoming(source, message)
    return Incoming(source, None, *sample_values(message))


def number(value: Any) -> bool:
    """A real number (``bool`` is an ``int`` in Python, but not a number here)."""
    return isinstance(value, int | float) and not isinstance(value, bool)
