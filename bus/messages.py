"""The message layer: what each section of the key space carries, built here and
checked here — the one gate every payload from the bus passes before a filter,
an encoder or a file sees it.

>>> from sonibus.bus.codec import encode
>>> from sonibus.bus.framing import frame
>>> gate = Gate()
>>> gate.check(Key.parse("pepper/frame"), encode(frame(1.5, 7, ["HeadYaw"], [0.1])))
{'t': 1.5, 'seq': 7, 'names': ['HeadYaw'], 'v': [0.1]}
>>> gate.check(Key.parse("pepper/frame"), encode(frame(1.5, 7, ["HeadYaw"], [1e300])))
Traceback (most recent call last):
...
sonibus.bus.messages.BadMessage: v[0] = 1e+300 is outside ±1e+06

Frames are built, and split into their keys' samples, in ``framing.py``. The rules
are the schemas' (``schemas/v1/``): their bounds are read from
there, and ``tests/test_messages.py`` checks that the gate and the schemas
agree. What only a running node can check is added here: ``t`` no further
ahead of this host's clock than ``Limits.max_future_s``, and payload sizes.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import hypot
from typing import Any

import jsonschema
from msgpack import unpackb

from .. import schemas
from .capped import Capped, size_of
from .codec import DecodeError, FrameDecoder, decode
from .keys import AUDIO_STREAMS, Key
from .layouts import Layouts
from .schemacheck import fits

__all__ = ["FRAME_FIELDS", "SECTIONS", "BadMessage", "Gate", "Limits", "Section", "number", "numbers", "schema_of"]

_FRAME = schemas.load("frame")["properties"]
MAX_JOINTS: int = _FRAME["names"]["maxItems"]          # joints in one frame
MAX_VALUE: float = _FRAME["v"]["items"]["maximum"]     # |v| of any joint or derived value (a physical bound)
MAX_SEQ: int = _FRAME["seq"]["maximum"]
MAX_DERIVED_SIZE: int = schemas.load("derived_sample")["properties"]["v"]["oneOf"][1]["maxItems"]
_DERIVED_FRAME = schemas.load("derived_frame")["properties"]
MAX_DERIVED_VALUES: int = _DERIVED_FRAME["names"]["maxItems"]  # derived values in one derived frame
MAX_STATS_ENTRIES: dict[str, int] = {name: table["maxProperties"] for name, table in
                                     schemas.load("node_stats")["properties"].items() if "maxProperties" in table}
MAX_DEPTH = 8                                          # nesting of lists and maps in an event
EVENT_KINDS = {rule["if"]["properties"]["kind"]["const"]: jsonschema.Draft202012Validator(rule["then"])
               for rule in schemas.load("event")["allOf"]}  # kind → its fields' rules, as the schema defines them
FRAME_FIELDS = ("t", "seq", "names", "v")  # a frame's own fields; every other one is a quantity per joint
_AUDIO = schemas.load("audio_chunk")
AUDIO_FIELDS = tuple(_AUDIO["required"])             # an audio chunk's fields, and no others
MIN_RATE: int = _AUDIO["properties"]["rate"]["minimum"]
MAX_RATE: int = _AUDIO["properties"]["rate"]["maximum"]
MAX_CHANNELS: int = _AUDIO["properties"]["channels"]["maximum"]
MAX_CHUNK_S: float = _AUDIO["x-max-duration-s"]      # an audio chunk's duration
_NAME = re.compile(_FRAME["names"]["items"]["pattern"].removesuffix("$") + r"\Z").match  # one plain key chunk
_DERIVED_NAME = re.compile(_DERIVED_FRAME["names"]["items"]["pattern"].removesuffix("$") + r"\Z").match  # feature/name


class BadMessage(ValueError):
    """A payload the gate refuses; the message says why in one line."""


@dataclass(frozen=True)
class Limits:
    """What the gate lets through beyond the schemas' own rules."""

    max_future_s: float = 5.0          # clock-skew tolerance: a t further ahead of this host's clock is refused
    max_payload: int = 64 * 1024       # bytes of any payload but robot info
    max_info_payload: int = 1 << 20    # bytes of a robot's info (joint table, behaviors)

    def payload_limit(self, section: str) -> int:
        """The most bytes of a payload in ``section`` of the key space."""
        return self.max_info_payload if section == "info" else self.max_payload


DEFAULT_LIMITS = Limits()  # (one object: gates of the defaults share verdicts by identity, bus/verdicts.py)


class Gate:
    """``check(key, payload)``: the decoded, checked message, or ``BadMessage``.

    One per node; it remembers the joint-name lists it has checked (a robot's
    are the same every frame), at most ``MAX_KNOWN`` of them."""

    MAX_KNOWN = 1024
    MAX_KNOWN_BYTES = 2 << 20  # of names in each table (a count alone let 1,024 lists of 128 long names pile up)

    def __init__(self, limits: Limits | None = None) -> None:
        self.limits = limits or DEFAULT_LIMITS
        self._known_names: Capped[tuple[str, ...], bool] = Capped(self.MAX_KNOWN, self.MAX_KNOWN_BYTES)
        # robot → the (checked) names of its last frame
        self._last_names: Capped[str, tuple[str, ...]] = Capped(self.MAX_KNOWN, self.MAX_KNOWN_BYTES)
        # robot → its last names and the reader of its frames of them, as ``FrameEncoder`` writes them
        # (None until a second frame comes with them: ``known_frame``)
        self._decoders: Capped[str, tuple[tuple[str, ...], FrameDecoder | None]] = Capped(
            self.MAX_KNOWN, 4 * self.MAX_KNOWN_BYTES)
        # derived frame's key → where its vectors are (its last frame's types), their sizes
        self._layouts = Layouts(MAX_DERIVED_SIZE, MAX_VALUE, self.MAX_KNOWN, self.MAX_KNOWN_BYTES)

    def check(self, key: Key, payload: bytes) -> dict[str, Any]:
        return self.verdict(key, payload)[0]

    def verdict(self, key: Key, payload: bytes) -> tuple[dict[str, Any], tuple[str, ...] | None]:
        """``check``, and what the check found beside the message: a frame's (or derived frame's)
        ``names`` as one immutable tuple, the same object for every frame of ``key``'s robot with
        the same names (what ``Selection`` keys its selection by, comparing no name again; its
        ``v`` is then known to be floats or ints within bounds), None for other messages."""
        section = SECTIONS.get(key.section)
        if section is None:
            raise BadMessage(f"'{key.section}' is not a section of the key space ({', '.join(SECTIONS)})")
        limit = self.limits.max_info_payload if key.section == "info" else self.limits.max_payload  # (payload_limit)
        if len(payload) > limit:
            raise BadMessage(f"payload of {len(payload)} bytes is over the limit of {limit}")
        message = None
        if payload.__class__ is bytes and payload:  # the usual: decoded here, one call less than codec.decode
            try:
                message = unpackb(payload, raw=False, strict_map_key=False)
            except Exception:  # (msgpack raises several unrelated types: codec.decode says which)
                message = None
        if message.__class__ is not dict:
            try:
                message = decode(payload)
            except DecodeError as exc:
                raise BadMessage(_cut(str(exc))) from None
        try:
            return message, section.check(self, key, message)
        except BadMessage:
            raise
        except (KeyError, TypeError, ValueError) as exc:  # a field missing or of the wrong type
            raise BadMessage(_reason(exc)) from None

    def known_frame(self, key: Key, payload: bytes) -> tuple[float, int, tuple[float, ...], tuple[str, ...]] | None:
        """A robot's frame (``key``: ``<robot>/frame``) with the names of its last one, in the bytes
        msgpack makes of a frame of floats (``codec.FrameDecoder``), checked as ``frame`` checks
        it: its ``t``, ``seq``, values and the names' tuple (the one ``verdict`` gives for them).
        None for anything else: another shape, a frame out of bounds, or one whose values' length
        as one vector passes ``MAX_VALUE`` (``verdict`` looks at each then); ``verdict`` says what
        it is. What every node pays a frame, without a string or a float made for each joint
        (issue 35). A decoder is made for the robot's names once they held over a frame: a robot
        whose names change every frame (two publishers of one name, a fuzzer) makes none.
        """
        last = self._last_names.get(key.robot)
        if last is None or len(payload) > self.limits.max_payload:
            return None
        names, decoder = self._decoders.get(key.robot) or (None, None)
        if names is not last:  # (names new since the robot's last frame: the next frame may make one)
            self._decoders.put(key.robot, (last, None), size_of(last) + len(key.robot))
            return None
        if decoder is None:
            decoder = FrameDecoder(last)
            self._decoders.put(key.robot, (last, decoder), decoder.size + len(key.robot))
        read = decoder.decode(payload)
        if read is None:
            return None
        t, seq, values = read  # (their types are the bytes': a float, an int, floats)
        if 0.0 <= t <= time.time() + self.limits.max_future_s and seq <= MAX_SEQ and hypot(*values) <= MAX_VALUE:
            return t, seq, values, last
        return None

    # -- sections ---------------------------------------------------------------------

    def _columns(self, message: dict[str, Any], most: int, what: str) -> tuple[list[Any], list[Any]]:
        """A frame's (or derived frame's) ``t`` and ``seq`` checked, and its ``names`` and ``v``:
        two lists of the same length, at most ``most`` long (``what``: what they list)."""
        self.stamp(message)
        names, values = message["names"], message["v"]
        if names.__class__ is not list or values.__class__ is not list or len(names) != len(values):
            raise BadMessage("names and v are not two lists of the same length")
        if len(names) > most:
            raise BadMessage(f"{len(names)} {what}, at most {most}")
        return names, values

    def frame(self, key: Key, message: dict[str, Any]) -> tuple[str, ...]:
        # (the usual frame's t, seq, names and v in one test, no call: what _columns checks, in its order,
        # each failure then said by _columns; the gate's per-frame cost is every node's, issue 35)
        t, seq = message["t"], message["seq"]
        names, values = message.get("names"), message.get("v")
        if not (t.__class__ is float and 0.0 <= t <= time.time() + self.limits.max_future_s
                and seq.__class__ is int and 0 <= seq <= MAX_SEQ
                and names.__class__ is list and values.__class__ is list and len(names) == len(values) <= MAX_JOINTS):
            names, values = self._columns(message, MAX_JOINTS, "joints in one frame")
        signature = tuple(names)  # (immutable: whoever takes the message may change its list)
        last = self._last_names.get(key.robot)
        if signature != last:  # (a robot's names are the same every frame: one comparison, the only one)
            self._known(names)
            # (robot and joint names come from the network: capped)
            last = self._last_names.put(key.robot, signature, size_of(names) + len(key.robot))
        if list(map(type, values)).count(float) != len(values) or not hypot(*values) <= MAX_VALUE:  # (plain_floats)
            numbers(values, "v")
        if len(message) == len(FRAME_FIELDS):  # (all four were read above: no quantity per joint beside v)
            return last
        for quantity, extra in message.items():
            if quantity in FRAME_FIELDS:
                continue
            if quantity.__class__ is not str or not _NAME(quantity):
                raise BadMessage(f"field {quantity!r} is not a plain name")
            if extra.__class__ is not list or len(extra) != len(names):
                raise BadMessage(f"{quantity} is not a list of {len(names)} numbers")
            numbers(extra, quantity)
        return last

    def _known(self, names: list[Any]) -> None:
        """``names`` checked (plain, unique), or one of the lists checked before."""
        try:
            signature = tuple(names)
            if signature in self._known_names:
                return
        except TypeError:  # (a name that is a list or a map: refused just below)
            pass
        self._check_names(names)
        self._known_names.put(signature, True, size_of(signature))  # (names made up on the fly: capped)

    def joint_sample(self, key: Key, message: dict[str, Any]) -> None:
        if not key.name:  # (<robot>/joints alone: a sink of pepper/** took it for a derived frame and failed)
            raise BadMessage(f"{key.key} names no joint: a joint's sample goes on <robot>/joints/<Joint>")
        self.stamp(message)
        for quantity, value in message.items():
            if quantity not in ("t", "seq"):
                if quantity.__class__ is not str or not _NAME(quantity):
                    raise BadMessage(f"field {quantity!r} is not a plain name")
                numbers((value,), quantity)
        if "v" not in message:
            raise BadMessage("no 'v'")

    def derived(self, key: Key, message: dict[str, Any]) -> tuple[str, ...] | None:
        """A derived frame (``<robot>/derived``) or a derived sample (``<robot>/derived/<feature>/<name>``)."""
        if key.name:
            self.derived_sample(key, message)
            return None
        return self.derived_frame(key, message)

    def derived_frame(self, key: Key, message: dict[str, Any]) -> tuple[str, ...]:
        # (the usual derived frame's t, seq, names and v in one test, no call, as ``frame``'s: what
        # _columns checks, in its order, each failure then said by _columns; every node that takes
        # derived values pays this a frame, issue 35)
        t, seq = message["t"], message["seq"]
        names, values = message.get("names"), message.get("v")
        if not (t.__class__ is float and 0.0 <= t <= time.time() + self.limits.max_future_s
                and seq.__class__ is int and 0 <= seq <= MAX_SEQ and names.__class__ is list
                and values.__class__ is list and len(names) == len(values) <= MAX_DERIVED_VALUES):
            names, values = self._columns(message, MAX_DERIVED_VALUES, "values in one derived frame")
        if len(message) != len(FRAME_FIELDS):
            extra = next(field for field in message if field not in FRAME_FIELDS)
            raise BadMessage(f"field {_short(extra)} is not one of a derived frame's ({', '.join(FRAME_FIELDS)})")
        signature = tuple(names)
        last = self._last_names.get(key.key)
        if signature != last:  # (a robot's names are the same every frame: one comparison, the only one)
            for name in names:
                if name.__class__ is not str or not _DERIVED_NAME(name):
                    raise BadMessage(f"derived name {_short(name)} is not <feature>/<name> of plain key chunks")
            if len(set(names)) != len(names):
                raise BadMessage("derived names are not unique")
            last = self._last_names.put(key.key, signature, size_of(names) + len(key.key))
        if self._layouts.plain(key.key, values):  # (the usual, in C: bus/layouts.py)
            return last
        for i, value in enumerate(values):  # (which one is wrong, and how)
            if value.__class__ is list:
                if not 0 < len(value) <= MAX_DERIVED_SIZE:
                    raise BadMessage(f"v[{i}] holds {len(value)} numbers, 1..{MAX_DERIVED_SIZE} expected")
                numbers(value, f"v[{i}]")
            else:
                numbers((value,), f"v[{i}]")
        return last

    def derived_sample(self, key: Key, message: dict[str, Any]) -> None:
        value = message.get("v")
        if isinstance(value, list):
            if not 0 < len(value) <= MAX_DERIVED_SIZE:
                raise BadMessage(f"v holds {len(value)} numbers, 1..{MAX_DERIVED_SIZE} expected")
            numbers(value, "v")
            message = {k: v for k, v in message.items() if k != "v"} | {"v": 0.0}
        self.joint_sample(key, message)

    def event(self, key: Key, message: dict[str, Any]) -> None:
        t, kind = message["t"], message["kind"]
        self._time(t)
        if kind.__class__ is not str or not kind:
            raise BadMessage(f"kind = {_short(kind)} is not a non-empty string")
        if kind != key.name:
            raise BadMessage(f"kind '{_cut(kind, 40)}' on {key.key}: an event's kind is the last chunk of its key")
        json_like(message, "event")
        fields = EVENT_KINDS.get(kind)
        if fields is not None:  # (only its kind's rules: the whole schema would cost 100 µs an event)
            _schema_check(fields, f"{kind} event", message)

    def audio(self, key: Key, message: dict[str, Any]) -> None:
        if key.name not in AUDIO_STREAMS:
            raise BadMessage(f"'{_cut(key.name, 40)}' is not an audio stream ({', '.join(AUDIO_STREAMS)})")
        self.stamp(message)
        rate, channels, pcm = message["rate"], message["channels"], message["pcm"]
        if rate.__class__ is not int or not MIN_RATE <= rate <= MAX_RATE:
            raise BadMessage(f"rate = {_short(rate)} is not an integer in {MIN_RATE}..{MAX_RATE} Hz")
        if channels.__class__ is not int or not 1 <= channels <= MAX_CHANNELS:
            raise BadMessage(f"channels = {_short(channels)} is not an integer in 1..{MAX_CHANNELS}")
        if pcm.__class__ is not bytes:
            raise BadMessage(f"pcm is a {type(pcm).__name__}, not bytes (int16 little-endian, interleaved)")
        width = 2 * channels
        if not pcm or len(pcm) % width:
            raise BadMessage(f"pcm of {len(pcm)} bytes is not a whole number of {channels}-channel int16 frames "
                             f"({width} bytes each, 1 at least)")
        if len(pcm) // width > rate * MAX_CHUNK_S:
            raise BadMessage(f"{len(pcm) // width} frames at {rate} Hz last "
                             f"{1000 * len(pcm) / width / rate:.0f} ms, at most {1000 * MAX_CHUNK_S:g} ms")
        if len(message) != len(AUDIO_FIELDS):
            extra = next(field for field in message if field not in AUDIO_FIELDS)
            raise BadMessage(f"field {_short(extra)} is not one of an audio chunk's ({', '.join(AUDIO_FIELDS)})")

    def info(self, key: Key, message: dict[str, Any]) -> None:
        json_like(message, "info")
        name = "derived_info" if key.name == "derived" else "robot_info"
        if not fits(name)(message):  # (the compiled check first: jsonschema only to say why it does not fit)
            _schema_check(schemas.validator(name), name.replace("_", " "), message)
        for joint in message.get("joints", ()):
            if not joint["min"] <= joint["max"]:
                raise BadMessage(f"joint {joint['name']}: min {joint['min']} is above max {joint['max']}")
        names = [joint["name"] for joint in message.get("joints", ())]
        if len(set(names)) != len(names):
            raise BadMessage("joint names are not unique")

    def command(self, key: Key, message: dict[str, Any]) -> None:
        json_like(message, "arguments")

    def node_stats(self, key: Key, message: dict[str, Any]) -> None:
        for table, most in MAX_STATS_ENTRIES.items():  # (first, and cheaply: a schema check of a big one takes ms)
            found = message.get(table)
            if isinstance(found, dict) and len(found) > most:
                raise BadMessage(f"{table}: {len(found)} entries, at most {most}")
        json_like(message, "stats")
        if not fits("node_stats")(message):  # (the compiled check first: jsonschema only to say why it does not fit)
            _schema_check(schemas.validator("node_stats"), "node stats", message)

    # -- shared -----------------------------------------------------------------------

    def stamp(self, message: dict[str, Any]) -> tuple[float, int]:
        """``t`` and ``seq`` of a sample or frame, checked."""
        t, seq = message["t"], message["seq"]
        self._time(t)
        if seq.__class__ is not int or not 0 <= seq <= MAX_SEQ:
            raise BadMessage(f"seq = {_short(seq)} is not an integer in 0..{MAX_SEQ}")
        return t, seq

    def _time(self, t: Any) -> None:
        if t.__class__ is not float and not number(t):
            raise BadMessage(f"t = {_short(t)} is not a number")
        if not 0 <= t <= time.time() + self.limits.max_future_s:  # (NaN fails too)
            raise BadMessage(f"t = {t!r} is not a time between 1970 and {self.limits.max_future_s:g} s from now"
                             " (clocks in step?)")

    @staticmethod
    def _check_names(names: list[Any]) -> None:
        for name in names:
            if name.__class__ is not str or not _NAME(name):
                raise BadMessage(f"joint name {_short(name)} is not one plain key chunk (no '/', wildcards or spaces)")
        if len(set(names)) != len(names):
            raise BadMessage("joint names are not unique")


@dataclass(frozen=True)
class Section:
    """One section of the key space (``<robot>/<section>/...``): the schema of its
    messages in ``schemas/v1/``, the gate's check of them, and how a sink takes them
    (``streams.Selection``; ``by_name``: audio, which most sinks cannot carry, and
    nodes' stats, which are about the bus, come only with a pattern that names them)."""

    name: str
    schema: str | None                                   # None: no one schema (a command's is its verb's)
    check: Callable[[Gate, Key, dict[str, Any]], tuple[str, ...] | None]  # (a frame's names: Gate.verdict)
    taken_as: str = "message"                            # "frame", "sample" (t, seq, values) or "message"
    by_name: bool = False                                # True: a sink takes it only where a pattern names it


SECTIONS: dict[str, Section] = {section.name: section for section in (
    Section("frame", "frame", Gate.frame, taken_as="frame"),
    Section("joints", "joint_sample", Gate.joint_sample, taken_as="sample"),
    # <robot>/derived: a derived frame (every value of one frame); <robot>/derived/<feature>/<name>: one value
    Section("derived", "derived_sample", Gate.derived, taken_as="sample"),
    Section("events", "event", Gate.event),
    Section("info", "robot_info", Gate.info),            # <robot>/info/derived: derived_info
    Section("cmd", None, Gate.command),
    # <robot>/program/<verb>: requests to a program that drives the robot (a show), checked like a command's
    # arguments; queries, never data: a sink takes none unless a pattern names the section
    Section("program", None, Gate.command, by_name=True),
    # <node>/maps/<verb>: a map node's requests (list, edit, learn, undo, save), checked like a program's
    Section("maps", None, Gate.command, by_name=True),
    Section("audio", "audio_chunk", Gate.audio, by_name=True),  # <robot>/audio/mic, <robot>/audio/speaker
    Section("stats", "node_stats", Gate.node_stats, by_name=True),  # sonibus/stats/<host>/<node>: about the bus
)}
"""Every section of the key space, the one table decoding, ``Streams`` and the recorder dispatch on."""


def schema_of(key: Key) -> str | None:
    """The name of the schema of messages on ``key`` (None: not a section's key, or a command)."""
    section = SECTIONS.get(key.section)
    if section is None:
        return None
    if key.section == "derived" and not key.name:
        return "derived_frame"
    return "derived_info" if key.section == "info" and key.name == "derived" else section.schema


def numbers(values: Sequence[Any], field: str) -> None:
    """Every value a finite number within ±``MAX_VALUE``; ``BadMessage`` naming the first that is not."""
    if plain_floats(values):
        return
    for i, v in enumerate(values):
        if not number(v):
            raise BadMessage(f"{field}[{i}] = {_short(v)} is not a number")
        if not -MAX_VALUE <= v <= MAX_VALUE:  # (NaN fails too)
            raise BadMessage(f"{field}[{i}] = {v!r} is outside ±{MAX_VALUE:g}")


def plain_floats(values: Sequence[Any]) -> bool:
    """Whether ``values`` are all floats whose length as a vector is within ``MAX_VALUE``:
    the usual frame, let through in two C loops (no Python code per value). False says
    nothing: ``numbers`` then looks at each value (an int, a large value or a bad one).

    >>> plain_floats([0.1, -2.0]), plain_floats([0.1, True]), plain_floats([float("nan")]), plain_floats([7])
    (True, False, False, False)
    """
    # (a bool is an int to hypot: the types first; hypot of values within ±MAX_VALUE can exceed it,
    # never the other way round, and it is NaN or inf when one of them is)
    return list(map(type, values)).count(float) == len(values) and hypot(*values) <= MAX_VALUE


def json_like(value: Any, what: str, depth: int = 0) -> None:
    """``value`` holds only what JSON can carry (maps with string keys, lists,
    strings, finite numbers, booleans, None), nested at most ``MAX_DEPTH`` deep."""
    if value is None or value.__class__ in (str, bool):
        return
    if value.__class__ is int:
        if not -(1 << 63) <= value < 1 << 64:
            raise BadMessage(f"{what}: integer {value} is too large")
        return
    if value.__class__ is float:
        if not math.isfinite(value):
            raise BadMessage(f"{what}: {value} is not a finite number")
        return
    if depth >= MAX_DEPTH:
        raise BadMessage(f"{what}: nested deeper than {MAX_DEPTH}")
    if value.__class__ is dict:
        for k, v in value.items():
            if k.__class__ is not str:
                raise BadMessage(f"{what}: key {_short(k)} is not a string")
            json_like(v, f"{what}.{k}" if depth < 2 else what, depth + 1)
        return
    if value.__class__ is list:
        for v in value:
            json_like(v, what, depth + 1)
        return
    raise BadMessage(f"{what}: {type(value).__name__} {_short(value)} cannot be carried (only JSON values)")


def _schema_check(validator: jsonschema.Validator, what: str, message: dict[str, Any]) -> None:
    error = next(validator.iter_errors(message), None)
    if error is not None:
        where = "/".join(str(p) for p in error.absolute_path)
        raise BadMessage(f"not a valid {what}: {where + ': ' if where else ''}{_cut(error.message)}")


def number(value: Any) -> bool:
    """A real number (``bool`` is an ``int`` in Python, but not a number here)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _short(value: Any) -> str:
    """``repr`` of a value, cut to fit in a one-line message."""
    return _cut(repr(value), 60)


def _cut(text: str, size: int = 120) -> str:
    text = " ".join(text.split())
    return text if len(text) <= size else text[:size - 3] + "..."


def _reason(exc: Exception) -> str:
    if isinstance(exc, KeyError):
        return f"no {exc.args[0]!r}" if exc.args else "a field is missing"
    return _cut(str(exc))

