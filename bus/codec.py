"""Payload codec: msgpack maps, Zenoh encoding ``application/msgpack``.

What a map must hold to be a frame, a sample or an event is the message
layer's business (``bus/messages.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import msgpack
import zenoh

ENCODING = zenoh.Encoding("application/msgpack")


class DecodeError(ValueError):
    """A payload is not a msgpack map."""


def encode(message: dict[str, Any]) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


@dataclass(frozen=True)
class Oversize:
    """What a subscription queues in place of a payload over the size limit
    (``messages.Limits``): its size only. A flood of huge payloads must not fill the
    memory before the gate refuses them; ``len()`` is the payload's size."""

    size: int

    def __len__(self) -> int:
        return self.size

    def __repr__(self) -> str:
        return f"<{self.size} bytes: over the size limit, not kept>"


def decode(payload: bytes | zenoh.ZBytes | Oversize | None) -> dict[str, Any]:
    data = payload
    if data.__class__ is not bytes:  # (bytes, as a subscription keeps them, are the usual case)
        if payload is None:
            return {}
        if isinstance(payload, Oversize):
            raise DecodeError(f"payload of {payload.size} bytes is over the size limit (not kept)")
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
