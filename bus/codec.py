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
        self._middle = _middle(self.names)

    def encode(self, t: float, seq: int, values: Sequence[float]) -> bytes:
        """The frame of ``values``, one per name, each a ``float`` (the caller's check:
        ``messages.plain_floats``; anything else would be packed as a float, not as msgpack packs it)."""
        if t.__class__ is not float or seq.__class__ is not int or not 0 <= seq < 1 << 32:  # (not a usual frame)
            return encode({"t": t, "seq": seq, "names": list(self.names), "v": list(values)})
        args = self._markers.copy()
        args[1::2] = values
        return b"".join((b"\x84\xa1t\xcb", _DOUBLE.pack(t), b"\xa3seq", _uint(seq), self._middle,
                         self._values.pack(*args)))


class FrameDecoder:
    """The frames of a robot with ``names`` read back from the bytes ``FrameEncoder`` writes
    (the bytes msgpack makes of ``{t, seq, names, v}``, every value a float): the names'
    bytes compared as they are and the values unpacked by one ``struct``, where msgpack
    made a string of each name and a float of each value, and the gate then compared the
    names and looked at the values' types one by one (issue 35: 30k of an OSC sink's 85k
    instructions a 17-joint frame). ``decode`` gives None for a frame of other names or of
    another shape, and for any other bytes (``unpackb`` reads those); a seq in a longer msgpack
    form than ``FrameEncoder`` writes is read as ``unpackb`` reads it. It never reads what
    msgpack would read otherwise.

    >>> frames = FrameDecoder(("HeadYaw", "HeadPitch"))
    >>> frames.decode(FrameEncoder(frames.names).encode(1.5, 300, [0.25, -1.0]))
    (1.5, 300, (0.25, -1.0))
    >>> frames.decode(encode({"t": 1.5, "seq": 300, "names": ["HeadYaw", "HeadPitch"], "v": [0.25, -1]})) is None
    True
    """

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names
        n = len(names)
        self._middle = _middle(names)
        self._markers = (b"\xcb",) * n  # (one byte each: Python's own bytes of it, compared by identity)
        # A frame's size tells its seq's width (msgpack's shortest form of it), the only part of
        # such a frame whose size varies: by size, one struct reads all of it, from its head to
        # its last value, the value markers as bytes between the values. (A name's bytes, the
        # seq's marker: compared, not read.)
        values = f"{len(self._middle)}s" + "cd" * n
        self._forms: dict[int, tuple[struct.Struct, bytes, int]] = {}
        # bytes it holds, about: five structs of 2n + 5 codes (~32 bytes a code), the names' bytes
        self.size = 5 * 32 * (2 * n + 5) + len(self._middle)
        for tag, seq, most in ((b"\xa3seq", "B", 0x7F), (b"\xa3seq\xcc", "B", 0xFF), (b"\xa3seq\xcd", "H", 0xFFFF),
                               (b"\xa3seq\xce", "I", 0xFFFF_FFFF), (b"\xa3seq\xcf", "Q", 0xFFFF_FFFF_FFFF_FFFF)):
            form = struct.Struct(f">4sd{len(tag)}s{seq}{values}")
            self._forms[form.size] = (form, tag, most)

    def decode(self, payload: bytes) -> tuple[float, int, tuple[float, ...]] | None:
        """``payload``'s ``t``, ``seq`` and values (a float per name), or None: not a frame of
        these names as ``FrameEncoder`` writes it (msgpack's own bytes for such a frame, any
        form of its seq)."""
        found = self._forms.get(len(payload))
        if found is None:
            return None
        form, tag, most = found
        fields = form.unpack(payload)
        if fields[0] != _HEAD or fields[2] != tag or fields[3] > most or fields[4] != self._middle \
                or fields[5::2] != self._markers:
            return None
        return fields[1], fields[3], fields[6::2]


_HEAD = b"\x84\xa1t\xcb"  # a map of 4, "t", a float64: how every frame FrameEncoder writes begins


def _middle(names: tuple[str, ...]) -> bytes:
    """A frame's bytes from its names' key to its values' first marker (``FrameEncoder``'s and
    ``FrameDecoder``'s): "names", their array, "v" and its array's header."""
    zeros = msgpack.packb([0.0] * len(names))  # (the array's header, then 9 bytes a value)
    return (b"\xa5names" + msgpack.packb(list(names), use_bin_type=True) + b"\xa1v"
            + zeros[:len(zeros) - 9 * len(names)])


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
