"""What a bus key becomes in an MCAP file: a channel named by the key, JSON
messages, and the JSON Schema of its section so Foxglove can plot it as is.

>>> schema_for("pepper/joints/HeadYaw")
'joint_sample'
>>> schema_for("pepper/info"), schema_for("pepper/events/speech"), schema_for("other/thing")
('robot_info', 'event', None)
>>> to_json({"t": 1.5, "seq": 3, "v": 0.25})
b'{"t":1.5,"seq":3,"v":0.25}'
"""

from __future__ import annotations

import json
from typing import Any

from sonibus.bus import messages
from sonibus.bus.keys import Key

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
SCHEMA_PREFIX = "sonibus.v1."
PROFILE = ""  # no MCAP well-known profile fits; channels carry plain JSON


def schema_for(key: str) -> str | None:
    """The name of the schema in ``sonibus.schemas`` for messages on ``key``, if any
    (``messages.SECTIONS``)."""
    try:
        return messages.schema_of(Key.parse(key))
    except ValueError:  # not a data key
        return None


def to_json(message: Any) -> bytes:
    """A message as compact, strict JSON bytes (what an MCAP ``json`` channel holds):
    ``ValueError`` for NaN or infinity, ``TypeError`` for what JSON has no type for."""
    return json.dumps(message, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()


def from_json(data: bytes) -> Any:
    return json.loads(data)
