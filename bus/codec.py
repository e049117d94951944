"""Payload codec: msgpack maps, Zenoh encoding ``application/msgpack``.

What a map must hold to be a frame, a sample or an event is the message
layer's business (``bus/messages.py``).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import msgpack
import zenoh

ENCODING = zenoh.Encoding("application/msgpack")


class DecodeError(ValueError):
    """A payload is not a msgpack map."""


def encode(message: dict[str, Any]) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


_DOUBLE = struct.Struct(">d")
_UINTS = ((1 << 8, struct.Struct(">BB"), 0xCC), (1 << 16, struct.Struct(">BH"), 0xCD),
          (1 << 32, struct.Struct(">BI"), 0xCE))


class FrameEncoder:
    """A robot's frames (``{t, seq, names, v}``, ``framing.frame``) encoded to the very bytes
    ``encode`` makes of them, the names packed once: a robot's joints are the same every frame,
    and their names were half the packing of a 17-joint frame (issue 35).

    >>> frames = FrameEncoder(["HeadYaw", "HeadPitch"])
    >>> frames.encode(1.5, 300, [0.25, -1.0]) == encode({"t": 1.5, "seq": 300, "names": ["HeadYaw", "HeadPitch"],
    ...                                                  "v": [0.25, -1.0]})
    True
    """

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        n = len(self.names)
        # msgpack writes a float as 0xcb and its 8 bytes: one struct for every value with its marker
        self._values = struct.Struct(">" + "Bd" * n)
        self._markers = [0xCB, 0.0] * n
        zeros = msgpack.packb([0.0] * n)  # (the array's header, then 9 bytes a value)
        self._middle = (b"\xa5names" + msgpack.packb(list(self.names), use_bin_type=True)
                        + b"\xa1v" + zeros[:len(zeros) - 9 * n])

    def encode(self, t: float, seq: int, values: Sequence[float]) -> bytes:
        """The frame of ``values``, one per name, each a ``float`` (the caller's check:
        ``messages.plain_floats``; anything else would be packed as a float, not as msgpack packs it)."""
        if t.__class__ is not float or seq.__class__ is not int or not 0 <= seq < 1 << 32:  # (not a usual frame)
            return encode({"t": t, "seq": seq, "names": list(self.names), "v": list(values)})
        args = self._markers.copy()
        args[1::2] = values
        return b"".join((b"\x84\xa1t\xcb", _DOUBLE.pack(t), b"\xa3seq", _uint(seq), self._middle,
                         self._values.pack(*args)))


def _uint(n: int) -> bytes:
    """``0 <= n < 2**32`` in msgpack's shortest form, as ``encode`` writes it."""
    if n < 0x80:
        return bytes((n,))
    for end, form, marker in _UINTS:
        if n < end:
            return form.pack(marker, n)
    raise ValueError(f"{n} is not below 2**32")


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
