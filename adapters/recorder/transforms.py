"""The transforms view (``<robot>/tf``, ``foxglove.FrameTransforms``) as JSON, each
transform's text kept from one frame to the next while it does not change.

Its JSON was the recorder's largest per-frame cost (issue 35): 12 transforms of
Pepper's arms, 2.9 KB and ~84 floats a frame, six times a frame's own JSON. A
transform is its joint's place in its parent's frame, so only the joints that
moved make a new one (with idle motion 2 of 12); the others are the text of the
frame before. The bytes are ``channels.to_json``'s, the same encoder's, byte for
byte (``tests/recorder/test_foxglove.py``).

>>> from sonibus.adapters.recorder.channels import to_json
>>> one = {"timestamp": {"sec": 1, "nsec": 5}, "parent_frame_id": "pepper/base_link",
...        "child_frame_id": "pepper/LShoulderPitch", "translation": {"x": 0.0, "y": 0.1, "z": 0.2},
...        "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
>>> message = {"transforms": [one, {**one, "timestamp": {"sec": 2, "nsec": 0}}]}
>>> transforms_json(message, to_json) == to_json(message)
True
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

FIELDS = ("timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation")
XYZ, XYZW = ("x", "y", "z"), ("x", "y", "z", "w")
MAX_KEPT = 4096  # transforms' texts kept (one per child frame; their names come from the network)

_NONE = object()  # (no timestamp encoded yet)
_BITS = struct.Struct("<7d").pack  # a transform's seven numbers, as the bits they are
_kept: dict[str, tuple[tuple[Any, bytes], bytes]] = {}  # child frame → ((parent, its numbers), its text)


def transforms_json(message: dict[str, Any], encode: Callable[[Any], bytes]) -> bytes:
    """``encode(message)`` for a ``foxglove.FrameTransforms`` message, the text of each transform
    that did not change since the last one of its child frame taken from then (a message of
    another shape is encoded whole)."""
    transforms = message.get("transforms")
    if len(message) != 1 or transforms.__class__ is not list:
        return encode(message)
    parts = []
    stamp: Any = _NONE
    stamped = b""
    for transform in transforms:
        if transform.__class__ is not dict or tuple(transform) != FIELDS:
            return encode(message)
        if transform["timestamp"] is not stamp:  # (a frame's transforms share theirs: encoded once)
            stamp = transform["timestamp"]
            stamped = b'{"timestamp":' + encode(stamp)
        parts.append(stamped + _rest(transform, encode))
    return b'{"transforms":[' + b",".join(parts) + b"]}"


def _rest(transform: dict[str, Any], encode: Callable[[Any], bytes]) -> bytes:
    """A transform's JSON after its timestamp (``,"parent_frame_id":...}``): kept while its
    values are the same to the bit (a float's text is its bits': 0.0 and -0.0 are two)."""
    translation, rotation, parent, child = (transform["translation"], transform["rotation"],
                                            transform["parent_frame_id"], transform["child_frame_id"])
    try:
        if tuple(translation) != XYZ or tuple(rotation) != XYZW or child.__class__ is not str:
            raise TypeError
        numbers = (translation["x"], translation["y"], translation["z"],
                   rotation["x"], rotation["y"], rotation["z"], rotation["w"])
        if any(number.__class__ is not float for number in numbers):  # (an int's text is not its float's)
            raise TypeError
        values: tuple[Any, bytes] | None = (parent, _BITS(*numbers))
    except TypeError:  # (not a transform as convert.py makes them: encoded as it is)
        values = None
    kept = _kept.get(child) if values is not None else None
    if kept is not None and kept[0] == values:
        return kept[1]
    text = b"," + encode({name: transform[name] for name in FIELDS[1:]})[1:]  # (without its brace)
    if values is not None:
        if len(_kept) >= MAX_KEPT:
            _kept.clear()
        _kept[child] = (values, text)
    return text
