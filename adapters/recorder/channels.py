"""What a bus key becomes in an MCAP file: a channel named by the key, JSON
messages, and the JSON Schema of its section so Foxglove can plot it as is.

>>> schema_for("pepper/joints/HeadYaw")
'joint_sample'
>>> schema_for("pepper/info"), schema_for("pepper/events/speech"), schema_for("other/thing")
('robot_info', 'event', None)
>>> to_json({"t": 1.5, "seq": 3, "v": 0.25})
b'{"t":1.5,"seq":3,"v":0.25}'

Audio chunks (``<robot>/audio/mic``, ``<robot>/audio/speaker``) carry bytes,
which JSON has no type for: their channels hold msgpack, as on the bus
(``encoding_of``), with the JSON Schema of their fields like the others.

>>> encoding_of("pepper/audio/mic"), encoding_of("pepper/joints/HeadYaw")
('msgpack', 'json')
>>> from_data("msgpack", to_data("pepper/audio/mic", {"t": 1.5, "pcm": b"PCM"}))
{'t': 1.5, 'pcm': b'PCM'}

Beside the bus's keys, a recording may hold views of them for Foxglove's panels
(``adapters/foxglove/views.py``): each frame whole, events as ``foxglove.Log``,
the arms as ``foxglove.FrameTransforms``, and the derived keys' units and
ranges. Readers of bus data (replay, export, plot) leave them out (``is_view``).

>>> is_view("pepper/tf"), is_view("pepper/frame"), is_view("pepper/joints/HeadYaw")
(True, True, False)
>>> channel_schema("pepper/log")[0], channel_schema("pepper/frame")[0], channel_schema("x")
('foxglove.Log', 'sonibus.v1.frame', None)
"""

from __future__ import annotations

import json
from typing import Any

from sonibus import schemas
from sonibus.adapters.foxglove.views import FOXGLOVE, TF, is_view
from sonibus.adapters.foxglove.wire import to_json as wire_json
from sonibus.bus import codec, messages
from sonibus.bus.keys import Key
from sonibus.schemas import foxglove

from .transforms import transforms_json

MESSAGE_ENCODING = "json"
AUDIO_ENCODING = "msgpack"  # not one of MCAP's well-known encodings: Foxglove lists these channels but cannot show them
SCHEMA_ENCODING = "jsonschema"
SCHEMA_PREFIX = "sonibus.v1."
PROFILE = ""  # no MCAP well-known profile fits; channels carry plain JSON
__all__ = ["channel_schema", "encoding_of", "from_data", "from_json", "is_view", "schema_for", "to_data", "to_json"]


def channel_schema(key: str) -> tuple[str, bytes] | None:
    """The name and JSON Schema (bytes) of channel ``key``: Foxglove's published one
    for its views, sonibus's (``sonibus.v1.<name>``) for bus keys, None for keys
    outside the key space."""
    foxglove_name = FOXGLOVE.get(key.partition("/")[2])
    if foxglove_name is not None:
        return foxglove_name, foxglove.data(foxglove_name)
    name = schema_for(key)
    return (SCHEMA_PREFIX + name, to_json(schemas.load(name))) if name is not None else None


def schema_for(key: str) -> str | None:
    """The name of the schema in ``sonibus.schemas`` for messages on ``key``, if any
    (``messages.SECTIONS``)."""
    try:
        return messages.schema_of(Key.parse(key))
    except ValueError:  # not a data key
        return None


def to_json(message: Any) -> bytes:
    """A message as compact, strict JSON bytes (what an MCAP ``json`` channel holds):
    ``ValueError`` for NaN or infinity, ``TypeError`` for what JSON has no type for.
    Foxglove's channels carry the same bytes: it is ``wire.to_json`` (``json``'s C encoder made
    once, samples written without it)."""
    return wire_json(message)


def from_json(data: bytes) -> Any:
    return json.loads(data)


def encoding_of(key: str) -> str:
    """The MCAP message encoding of channel ``key``: msgpack for audio, JSON for the rest."""
    parts = key.split("/")
    return AUDIO_ENCODING if len(parts) == 3 and parts[1] == "audio" else MESSAGE_ENCODING


def to_data(key: str, message: Any) -> bytes:
    """``message`` as channel ``key`` holds it (``encoding_of``); ``ValueError`` or
    ``TypeError`` for what its encoding cannot carry."""
    if encoding_of(key) == AUDIO_ENCODING:
        return codec.encode(message)
    if key.partition("/")[2] == TF:  # (the arms' transforms, made every frame: what did not move is kept)
        return transforms_json(message, to_json)
    return to_json(message)


def from_data(encoding: str, data: bytes) -> Any:
    """A message out of a channel of ``encoding``; ``ValueError`` if not one of sonibus's."""
    if encoding == AUDIO_ENCODING:
        return codec.decode(data)
    if encoding == MESSAGE_ENCODING:
        return from_json(data)
    raise ValueError(f"{encoding}, not {MESSAGE_ENCODING} or {AUDIO_ENCODING}")
