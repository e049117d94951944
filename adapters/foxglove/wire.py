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
from typing import Any

TEXT, BINARY = 0x1, 0x2  # WebSocket opcodes (RFC 6455 5.2)
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")  # the SDK's name, and ws-protocol's (Lichtblick)
MESSAGE_DATA = 1     # the server's binary opcode of a message
WARNING, ERROR = 1, 2  # a status message's levels (0: info)
MAX_ID = 2**32 - 1   # ids are uint32
_HEADER = struct.Struct("<BIQ")
_SUBSCRIPTION = struct.Struct("<I")
_TIME = struct.Struct("<Q")
_JSON = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode  # (made once:
# json.dumps with options makes an encoder at every call, ~1 µs of 45 messages a frame)


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
    """
    return _JSON(message).encode()


def frame_header(opcode: int, length: int) -> bytes:
    """The header of a whole, unmasked WebSocket frame of ``length`` bytes (a server's: RFC 6455
    5.2, FIN set, no extension), as aiohttp writes it: the hub writes what is due to a client
    in one transport write, frames and all (docs/foxglove.md, "How messages are sent")."""
    if length < 126:
        return bytes((0x80 | opcode, length))
    if length < 1 << 16:
        return bytes((0x80 | opcode, 126)) + length.to_bytes(2, "big")
    return bytes((0x80 | opcode, 127)) + length.to_bytes(8, "big")


def data_frame(log_time_ns: int, payload: bytes) -> tuple[bytes, bytes]:
    """A message's WebSocket frame but for its subscription id, made once for every client:
    ``(head, tail)``; a client's frame is ``head + subscription(id) + tail``."""
    return (frame_header(BINARY, _HEADER.size + len(payload)) + bytes((MESSAGE_DATA,)),
            _TIME.pack(log_time_ns) + payload)


def subscription(id_: int) -> bytes:
    """A subscription id as a message carries it (between ``data_frame``'s head and tail)."""
    return _SUBSCRIPTION.pack(id_)


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
