"""OSC arguments → a command's request map, in the order of its schema's properties.

The main string (``x-positional`` in the schema: say's text, a behavior's or
posture's name) takes every string in a row, joined by spaces, since Pure Data
splits a message into words. Only the shape is checked here (how many
arguments, which OSC types); ranges, joints, behaviors and postures are the
robot owner's to validate.

>>> request("say", ["hello", "there", 0.5])
{'text': 'hello there', 'volume': 0.5}
>>> request("joints/set", ["HeadYaw", 0.3, "HeadPitch", -0.1, 0.5])
{'names': ['HeadYaw', 'HeadPitch'], 'angles': [0.3, -0.1], 'speed': 0.5}
>>> request("stiffness", ["Head", "LArm", 1])
{'names': ['Head', 'LArm'], 'value': 1.0}
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sonibus import schemas
from sonibus.bus.errors import CommandError

KINDS = {"number": "a number", "integer": "an integer", "string": "a string",
         "boolean": "T, F, 0 or 1", "array": "strings"}
OSC_NAMES = {"str": "string", "list": "array", "tuple": "MIDI or time tag"}


def request(verb: str, args: Sequence[Any]) -> dict[str, Any]:
    """The request for ``verb``, or ``CommandError("bad_request")`` when ``args``
    cannot be shaped. ``stop`` ignores its arguments; an unknown verb is sent
    without any (the robot answers ``unknown_verb`` with the list)."""
    if verb == "stop" or verb not in schemas.command_verbs():
        return {}
    if verb == "joints/set":
        return _joint_pairs(args)
    schema = schemas.command_schema(verb)
    props = schema.get("properties", {})
    out: dict[str, Any] = {}
    index = 0
    for name, prop in props.items():
        if index >= len(args):
            break
        joined = name == schema.get("x-positional") and prop.get("type") == "string"
        if prop.get("type") == "array" or joined:  # a run of strings: stiffness "Head" "LArm" 1.0
            run = 0
            while index + run < len(args) and isinstance(args[index + run], str):
                run += 1
            if not run:
                raise _bad(verb, index, name, prop, args[index])
            words = list(args[index:index + run])
            out[name] = " ".join(words) if joined else words  # Pd sends say's text word by word
            index += run
        else:
            out[name] = _typed(verb, index, name, prop, args[index])
            index += 1
    if index < len(args):
        takes = f"takes {' '.join(props)}" if props else "takes no arguments"
        raise CommandError("bad_request", f"{verb} {takes}: argument {index + 1} ({_shown(args[index])}) "
                           f"has no place")
    return out


def _joint_pairs(args: Sequence[Any]) -> dict[str, Any]:
    """``"HeadYaw" 0.3 ["HeadPitch" -0.1 ...] [speed]``."""
    names: list[str] = []
    angles: list[float] = []
    index = 0
    while index < len(args) and isinstance(args[index], str):
        if index + 1 >= len(args) or not _number(args[index + 1]):
            after = _shown(args[index + 1]) if index + 1 < len(args) else "nothing"
            raise CommandError("bad_request", f"joints/set: joint {args[index][:40]!r} (argument {index + 1}) "
                               f"must be followed by its angle, got {after}")
        names.append(args[index])
        angles.append(float(args[index + 1]))
        index += 2
    out: dict[str, Any] = {"names": names, "angles": angles}
    rest = args[index:]
    if len(rest) == 1 and _number(rest[0]):
        out["speed"] = float(rest[0])
    elif rest:
        raise CommandError("bad_request", f"joints/set: expected \"Joint\" angle pairs and an optional speed, "
                           f"argument {index + 1} is {_shown(rest[0])}")
    return out


def _typed(verb: str, index: int, name: str, prop: dict[str, Any], value: Any) -> Any:
    kind = prop.get("type")
    if kind == "number" and _number(value):
        return float(value)
    if kind == "integer" and _number(value) and float(value).is_integer():
        return int(value)
    if kind == "string" and isinstance(value, str):
        return value
    if kind == "boolean" and (isinstance(value, bool) or (_number(value) and value in (0, 1))):
        return bool(value)
    raise _bad(verb, index, name, prop, value)


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _bad(verb: str, index: int, name: str, prop: dict[str, Any], value: Any) -> CommandError:
    want = KINDS.get(prop.get("type", ""), prop.get("type", "?"))
    return CommandError("bad_request", f"{verb}: argument {index + 1} ({name}) must be {want}, got {_shown(value)}")


def _shown(value: Any) -> str:
    if isinstance(value, bytes):
        return f"a blob of {len(value)} bytes"
    if value is None:
        return "nil"
    text = repr(value)
    kind = OSC_NAMES.get(type(value).__name__, type(value).__name__)
    return f"{kind} {text[:40]}{'...' if len(text) > 40 else ''}"
