"""Foxglove's WebSocket protocol, the server's side of what sonibus uses: pure functions,
no sockets (``hub.py`` serves them). The protocol is ws-protocol's ``foxglove.websocket.v1``
(docs/spec.md of github.com/foxglove/ws-protocol), which Foxglove's SDK serves unchanged as
``foxglove.sdk.v1``: both names are accepted. Only what a viewer needs: ``serverInfo``,
``advertise``, ``unadvertise``, ``status``, and messages (binary opcode 1) of the
subscriptions a client asks for; no capability is advertised (so no ``time`` message: a
viewer keeps its own clock), so a client sends only ``subscribe`` and ``unsubscribe``.

>>> server_info("sonibus", "s1", {"sonibus": "1.0"})
{'op': 'serverInfo', 'name': 'sonibus', 'capabilities': [], 'metadata': {'sonibus': '1.0'}, 'sessionId': 's1'}
>>> unadvertise([3, 4])
{'op': 'unadvertise', 'channelIds': [3, 4]}
>>> message_data(7, 1_500_000_000, b'{"v":1}').hex(" ")
'01 07 00 00 00 00 2f 68 59 00 00 00 00 7b 22 76 22 3a 31 7d'
>>> [frame_header(TEXT, n).hex(" ") for n in (5, 126, 70_000)]  # a WebSocket frame's, the server's
['81 05', '81 7e 00 7e', '81 7f 00 00 00 00 00 01 11 70']
>>> parse('{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 3}]}')
('subscribe', [(1, 3)])
>>> parse('{"op": "unsubscribe", "subscriptionIds": [1]}')
('unsubscribe', [1])
>>> parse('{"op": "advertise", "channels": []}')  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
sonibus.adapters.foxglove.wire.Refused: op 'advertise' is not served (this server advertises no capability: ...)
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from json.encoder import c_make_encoder, encode_basestring
from typing import Any

TEXT, BINARY = 0x1, 0x2  # WebSocket opcodes (RFC 6455 5.2)
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")  # the SDK's name, and ws-protocol's (Lichtblick)
MESSAGE_DATA = 1     # the server's binary opcode of a message
WARNING, ERROR = 1, 2  # a status message's levels (0: info)
MAX_ID = 2**32 - 1   # ids are uint32
_HEADER = struct.Struct("<BIQ")
_SUBSCRIPTION = struct.Struct("<I")
_TIME = struct.Struct("<Q")
_ENCODER = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False)
# ``_ENCODER``'s C encoder itself, made once (``JSONEncoder.encode`` makes one at every call: 1.6 µs of a
# sample's 5.2); no check of circular references (``markers`` None: a message decoded from the bus
# cannot hold itself; one made to would raise RecursionError), else the same bytes and errors
_C_JSON = c_make_encoder(None, _ENCODER.default, encode_basestring, None, ":", ",", False, False, False) \
    if c_make_encoder is not None else None
_SAMPLE = ("t", "seq", "v")
_float = float.__repr__  # (what json writes for a float: its repr; for an int, its int's)
_prefix: tuple[Any, Any, str] = (None, None, "")  # (t, seq, '{"t":...,"seq":...,"v":') of the last sample


class Refused(ValueError):
    """A client message this server does not take (the reason, for a ``status``)."""


@dataclass(frozen=True)
class Channel:
    """A channel as ``advertise`` describes it."""

    id: int
    topic: str
    encoding: str
    schema_name: str
    schema: str
    schema_encoding: str


def server_info(name: str, session_id: str, metadata: dict[str, str]) -> dict[str, Any]:
    """The first message to every client (``supportedEncodings`` left out: the spec sets it only
    for client publishing and services, which are not served)."""
    return {"op": "serverInfo", "name": name, "capabilities": [], "metadata": metadata, "sessionId": session_id}


def advertise(channels: list[Channel]) -> dict[str, Any]:
    return {"op": "advertise", "channels": [
        {"id": c.id, "topic": c.topic, "encoding": c.encoding, "schemaName": c.schema_name, "schema": c.schema,
         "schemaEncoding": c.schema_encoding} for c in channels]}


def unadvertise(ids: list[int]) -> dict[str, Any]:
    return {"op": "unadvertise", "channelIds": ids}


def status(message: str, level: int = ERROR) -> dict[str, Any]:
    return {"op": "status", "level": level, "message": message}


def message_data(subscription: int, log_time_ns: int, payload: bytes) -> bytes:
    """One message of a subscription, as the client decodes it (little-endian ids and time)."""
    return _HEADER.pack(MESSAGE_DATA, subscription, log_time_ns) + payload


def to_json(message: Any) -> bytes:
    """A message as a channel's payload: compact, strict JSON (``recorder.channels.to_json``'s
    bytes, as a recording holds them); ``ValueError`` for NaN or infinity, ``TypeError`` for
    what JSON has no type for.

    >>> to_json({"t": 1.5, "seq": 7, "v": 0.25, "name": "é"})
    b'{"t":1.5,"seq":7,"v":0.25,"name":"\\xc3\\xa9"}'

    A sample ``{"t": float, "seq": int, "v": float}`` (a joint's, a derived value's: 43 of the
    45 messages of a frame in the show) is written without the encoder (issue 35): its ``t``
    and ``seq`` once for the samples of a frame (they share them), its ``v`` as json writes
    it (``float.__repr__``); any other message, or a sample of another type or not finite,
    goes through the encoder. The bytes are the same (``tests/foxglove/test_json.py``).
    """
    global _prefix
    if message.__class__ is dict and len(message) == 3:
        t, seq, v = message.get("t"), message.get("seq"), message.get("v")
        if t.__class__ is float and seq.__class__ is int and v.__class__ is float and v - v == 0.0:
            prefix = _prefix  # (one read: another thread may set it meanwhile)
            if prefix[0] is not t or prefix[1] is not seq:  # (held there, so not another object at its address)
                if t - t != 0.0 or tuple(message) != _SAMPLE:
                    return encode(message)
                prefix = _prefix = (t, seq, f'{{"t":{_float(t)},"seq":{int.__repr__(seq)},"v":')
            elif tuple(message) != _SAMPLE:
                return encode(message)
            return f"{prefix[2]}{_float(v)}}}".encode()
    return encode(message)


def encode(message: Any) -> bytes:
    """``message`` as compact, strict JSON by the encoder (``json``'s, in C when there is one)."""
    if _C_JSON is None:
        return _ENCODER.encode(message).encode()
    return "".join(_C_JSON(message, 0)).encode()


def frame_header(opcode: int, length: int) -> bytes:
    """The header of a whole, unmasked WebSocket frame of ``length`` bytes (a server's: RFC 6455
    5.2, FIN set, no extension), as aiohttp writes it: the hub writes what is due to a client
    in one transport write, frames and all (docs/foxglove.md, "How messages are sent")."""
    if length < 126:
        return bytes((0x80 | opcode, length))
    if length < 1 << 16:
        return bytes((0x80 | opcode, 126)) + length.to_bytes(2, "big")
    return bytes((0x80 | opcode, 127)) + length.to_bytes(8, "big")


_SHORT_HEADS = [frame_header(BINARY, _HEADER.size + n) + bytes((MESSAGE_DATA,)) for n in range(126 - _HEADER.size)]


def data_head(length: int) -> bytes:
    """The start of a message's WebSocket frame, up to its subscription id, for a payload of
    ``length`` bytes; a client's frame is ``data_head + subscription(id) + stamp(log time) +
    payload`` (parts made once for every client and every message of a time: ``hub.py``).

    >>> parts = (data_head(7), subscription(7), stamp(1_500_000_000), b'{"v":1}')
    >>> b"".join(parts) == frame_header(BINARY, 20) + message_data(7, 1_500_000_000, b'{"v":1}')
    True
    """
    if length < 126 - _HEADER.size:
        return _SHORT_HEADS[length]
    return frame_header(BINARY, _HEADER.size + length) + bytes((MESSAGE_DATA,))


def subscription(id_: int) -> bytes:
    """A subscription id as a message carries it (after ``data_head``)."""
    return _SUBSCRIPTION.pack(id_)


def stamp(log_time_ns: int) -> bytes:
    """A log time as a message carries it (after its subscription id)."""
    return _TIME.pack(log_time_ns)


def parse(text: str) -> tuple[str, list[Any]]:
    """A client's text message: ``("subscribe", [(subscription id, channel id), ...])`` or
    ``("unsubscribe", [subscription id, ...])``; ``Refused`` saying why for anything else."""
    try:
        message = json.loads(text)
    except (ValueError, RecursionError):
        raise Refused(f"not JSON: {text[:60]!r}") from None
    op = message.get("op") if isinstance(message, dict) else None
    if op == "subscribe":
        items = message.get("subscriptions")
        if not isinstance(items, list) or not all(isinstance(s, dict) for s in items):
            raise Refused("subscribe: 'subscriptions' must be a list of {\"id\", \"channelId\"}")
        return op, [(_id(s.get("id"), "id"), _id(s.get("channelId"), "channelId")) for s in items]
    if op == "unsubscribe":
        ids = message.get("subscriptionIds")
        if not isinstance(ids, list):
            raise Refused("unsubscribe: 'subscriptionIds' must be a list of subscription ids")
        return op, [_id(i, "subscriptionIds") for i in ids]
    if isinstance(op, str):
        raise Refused(f"op {op[:40]!r} is not served (this server advertises no capability: subscribe and "
                      "unsubscribe only)")
    raise Refused(f"a message without an op: {text[:60]!r}")


def _id(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_ID:
        raise Refused(f"{name} {str(value)[:20]!r} is not an id (an integer in [0, 2^32))")
    return value
