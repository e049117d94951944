"""What the fuzzer sends: per family, Hypothesis strategies of valid, malformed and
hostile inputs, each an ``Input`` that knows where it goes and whether it is valid.

Families: ``frame`` (``pepper/frame``), ``joint`` (``pepper/joints/<J>``),
``derived`` (``pepper/derived/<feature>/<name>``), ``event``
(``pepper/events/<kind>``), ``command`` (queries on ``pepper/cmd/<verb>``),
``info`` (queries on ``pepper/info``…, and robots whose info replies are
garbage), ``osc`` (UDP packets to the gateway). ``burst`` repeats one input of
another family at high rate.

Validity is decided here, by construction, never by asking the product: a
valid command carries a ``signature`` that a ``command`` event with ``ok =
true`` must match (``Oracle``); every other executed command came from invalid
input.
"""

from __future__ import annotations

import json
import math
import struct
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import msgpack
from hypothesis import strategies as st

from sonibus.bus.robot import load_model

ROBOT = "pepper"
MODEL = load_model(ROBOT)
JOINTS = [(j.name, j.min, j.max) for j in MODEL.joints]
NAMES = [name for name, _, _ in JOINTS]
HEY = "animations/Stand/Gestures/Hey_1"
FEATURES = [("velocity", "HeadYaw"), ("hand", "L"), ("hand_speed", "R"), ("qom", "Head"), ("qom", "Body")]
EVENT_KINDS = ["behavior", "speech", "posture", "connection", "motion", "command", "custom"]
VERBS = ["say", "behavior/run", "behavior/stop", "behavior/list", "posture", "joints/set", "stiffness",
         "awareness", "stop"]

VALID, MALFORMED, HOSTILE = "valid", "malformed", "hostile"


@dataclass(frozen=True)
class Input:
    """One thing to send: ``how`` is ``put``, ``query`` or ``osc``; ``signature`` is set
    for commands that are valid (they may run), ``None`` for every other input."""

    family: str
    label: str          # valid, malformed, hostile
    how: str
    key: str            # Zenoh key, or the OSC address (for the report)
    payload: bytes
    signature: str | None = None
    note: str = ""      # what makes it bad, for reports

    def describe(self) -> str:
        head = self.payload[:120]
        return f"{self.family}/{self.label} {self.how} {self.key} {self.note} payload={head!r}" + \
            (f"... ({len(self.payload)} bytes)" if len(self.payload) > 120 else "")


def pack(value: Any) -> bytes:
    return msgpack.packb(value, use_bin_type=True)


def signature(verb: str, args: Any) -> str:
    """What a ``command`` event of a valid command carries, comparable across OSC's
    float32 rounding; ``stop`` runs whatever its arguments."""
    if verb == "stop":
        return "stop"
    return verb + " " + json.dumps(_rounded(args), sort_keys=True)


def _rounded(value: Any) -> Any:
    if isinstance(value, bool):
        return value
    if isinstance(value, float):
        return round(value, 4)
    if isinstance(value, dict):
        return {str(k): _rounded(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_rounded(v) for v in value]
    return value


# -- values ----------------------------------------------------------------------------

INT = st.integers(min_value=-(2 ** 63), max_value=2 ** 64 - 1)  # what msgpack can carry
HOSTILE_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 3.5e38, 1e6 + 1, -1e7,
                                  5e-324, 2.0 ** 63, 0.0])
ODD = st.one_of(
    st.none(), st.booleans(), st.binary(max_size=16), st.text(max_size=8),
    INT,
    st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=8)),
    st.lists(INT, max_size=3), st.dictionaries(st.text(max_size=3), INT, max_size=2),
)
BAD_T = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf, 1e12, -1.0, 0.0, 1e300]),
                  st.builds(lambda d: time.time() + d, st.sampled_from([3600.0, 86400.0 * 365, 30.0, -86400.0])),
                  ODD)
BAD_SEQ = st.one_of(st.sampled_from([-1, -(2 ** 63), 2 ** 64 - 1, 2 ** 63]), st.floats(allow_nan=True), ODD)
BAD_NAMES = st.sampled_from(["", "a/b", "*", "**", "$*", "Head$Yaw", "a*b", "ç", "x" * 300, "Head Yaw", "\0",
                             "line\nbreak", "HeadYaw/../x"])


def _value(joint: int) -> st.SearchStrategy[float]:
    _, lo, hi = JOINTS[joint]
    return st.floats(min_value=lo, max_value=hi, allow_nan=False)


def _oversize(what: str) -> dict[str, Any]:
    return {"t": time.time(), "seq": 1, "kind": what, "blob": "x" * 200_000}


# -- frames -------------------------------------------------------------------------------

@st.composite
def valid_frame(draw: st.DrawFn) -> dict[str, Any]:
    chosen = draw(st.lists(st.integers(0, len(JOINTS) - 1), min_size=1, max_size=len(JOINTS), unique=True))
    return {"t": time.time(), "seq": draw(st.integers(0, 2 ** 31)), "names": [NAMES[i] for i in chosen],
            "v": [draw(_value(i)) for i in chosen]}


@st.composite
def bad_frame(draw: st.DrawFn) -> tuple[str, Any]:
    frame = draw(valid_frame())
    n = len(frame["names"])
    how = draw(st.sampled_from(["t", "seq", "name", "dup", "value", "short", "long", "types", "missing",
                                "extra_list", "many", "nonmap", "bytes", "ext", "garbage", "oversize"]))
    if how == "t":
        frame["t"] = draw(BAD_T)
    elif how == "seq":
        frame["seq"] = draw(BAD_SEQ)
    elif how == "name":
        frame["names"][draw(st.integers(0, n - 1))] = draw(BAD_NAMES)
    elif how == "dup":
        frame["names"] = frame["names"] + frame["names"][:1]
        frame["v"] = frame["v"] + frame["v"][:1]
    elif how == "value":
        frame["v"][draw(st.integers(0, n - 1))] = draw(st.one_of(HOSTILE_FLOATS, ODD))
    elif how == "short":
        frame["v"] = frame["v"][:-1]
    elif how == "long":
        frame["v"] = frame["v"] + [0.1] * draw(st.integers(1, 5))
    elif how == "types":
        field = draw(st.sampled_from(["t", "seq", "names", "v"]))
        frame[field] = draw(ODD)
    elif how == "missing":
        del frame[draw(st.sampled_from(["t", "seq", "names", "v"]))]
    elif how == "extra_list":
        frame[draw(st.sampled_from(["cmd", "cur", "temp"]))] = draw(st.one_of(ODD, st.lists(HOSTILE_FLOATS)))
    elif how == "many":
        count = draw(st.sampled_from([129, 500, 2000]))
        frame["names"] = [f"Fake{i}" for i in range(count)]
        frame["v"] = [0.1] * count
    elif how == "nonmap":
        return how, draw(st.one_of(st.lists(st.floats(), max_size=4), INT, st.text(max_size=10),
                                   st.none()))
    elif how == "bytes":
        return how, draw(st.binary(max_size=64))
    elif how == "ext":
        frame["v"] = [msgpack.ExtType(draw(st.integers(0, 127)), b"\x00\x01")] * n
    elif how == "garbage":
        return how, b"\xc1" + draw(st.binary(max_size=32))  # 0xc1: never valid msgpack
    elif how == "oversize":
        frame["names"].append("x" * 100_000)
        frame["v"].append(0.0)
    return how, frame


def _payload(value: Any) -> bytes:
    return value if isinstance(value, bytes) else pack(value)


def frames() -> st.SearchStrategy[Input]:
    key = f"{ROBOT}/frame"
    valid = valid_frame().map(lambda f: Input("frame", VALID, "put", key, pack(f)))
    bad = bad_frame().map(lambda h: Input("frame", HOSTILE if h[0] in ("many", "oversize", "ext") else MALFORMED,
                                          "put", key, _payload(h[1]), note=h[0]))
    return st.one_of(valid, bad, bad)


def huge_frame(joints: int = 50_000) -> Input:
    """Issue 13's 50,000 made-up joints in one frame."""
    frame = {"t": time.time(), "seq": 7, "names": [f"Made{i}" for i in range(joints)], "v": [0.25] * joints}
    return Input("frame", HOSTILE, "put", f"{ROBOT}/frame", pack(frame), note=f"{joints} joints")


# -- joint samples and derived values ------------------------------------------------------------

@st.composite
def _sample(draw: st.DrawFn, section: str) -> Input:
    family = "joint" if section == "joints" else "derived"
    if section == "joints":
        index = draw(st.integers(0, len(JOINTS) - 1))
        key, value = f"{ROBOT}/joints/{NAMES[index]}", draw(_value(index))
    else:
        feature, name = draw(st.sampled_from(FEATURES))
        key = f"{ROBOT}/derived/{feature}/{name}"
        value = [0.1, 0.2, 0.3] if feature == "hand" else 0.5
    sample: Any = {"t": time.time(), "seq": draw(st.integers(0, 2 ** 31)), "v": value}
    how = draw(st.sampled_from(["valid", "valid", "t", "seq", "v", "vlist", "types", "missing", "nonmap", "bytes",
                                "ext", "oversize", "key"]))
    if how == "valid":
        return Input(family, VALID, "put", key, pack(sample))
    if how == "t":
        sample["t"] = draw(BAD_T)
    elif how == "seq":
        sample["seq"] = draw(BAD_SEQ)
    elif how == "v":
        sample["v"] = draw(st.one_of(HOSTILE_FLOATS, ODD))
    elif how == "vlist":
        sample["v"] = draw(st.lists(st.one_of(HOSTILE_FLOATS, st.floats()), min_size=0, max_size=2000))
    elif how == "types":
        sample[draw(st.sampled_from(["t", "seq", "v", "cmd", "cur", "temp"]))] = draw(ODD)
    elif how == "missing":
        del sample[draw(st.sampled_from(["t", "seq", "v"]))]
    elif how == "nonmap":
        sample = draw(st.one_of(st.lists(st.floats(), max_size=3), INT, st.text(max_size=6)))
    elif how == "bytes":
        return Input(family, MALFORMED, "put", key, draw(st.binary(max_size=48)), note=how)
    elif how == "ext":
        sample["v"] = msgpack.ExtType(5, b"\x00" * 8)
    elif how == "oversize":
        sample["note"] = "x" * 200_000
    elif how == "key":  # a name that is no joint of the robot, or a nested key
        key = draw(st.sampled_from([f"{ROBOT}/{section}/NoSuchJoint", f"{ROBOT}/{section}/a/b/c",
                                    f"{ROBOT}/{section}/" + "y" * 200, f"{ROBOT}/{section}/ç"]))
        return Input(family, MALFORMED, "put", key, pack(sample), note=how)
    label = HOSTILE if how in ("vlist", "ext", "oversize") else MALFORMED
    return Input(family, label, "put", key, pack(sample), note=how)


def joints() -> st.SearchStrategy[Input]:
    return _sample("joints")


def derived() -> st.SearchStrategy[Input]:
    return _sample("derived")


# -- events ---------------------------------------------------------------------------

def _nested(depth: int) -> Any:
    value: Any = 1
    for _ in range(depth):
        value = {"a": [value]}
    return value


@st.composite
def events(draw: st.DrawFn) -> Input:
    kind = draw(st.sampled_from(EVENT_KINDS))
    key = f"{ROBOT}/events/{kind}"
    event: Any = {"t": time.time(), "kind": kind, "name": HEY, "state": "started"}
    how = draw(st.sampled_from(["valid", "valid", "bytes_field", "ext", "nested", "huge", "nan", "t", "kind",
                                "nonmap", "garbage", "many_fields", "key"]))
    if how == "valid":
        return Input("event", VALID, "put", key, pack(event))
    if how == "bytes_field":
        event[draw(st.sampled_from(["name", "state", "text", "kind"]))] = draw(st.binary(max_size=16))
    elif how == "ext":
        event["name"] = msgpack.ExtType(draw(st.integers(0, 127)), b"xyz")
    elif how == "nested":
        depth = draw(st.sampled_from([50, 250, 5000]))
        if depth > 250:  # deeper than msgpack packs: a list in a list ... written by hand
            event["detail"] = 0
            return Input("event", HOSTILE, "put", key, pack(event)[:-1] + b"\x91" * depth + b"\x00", note=how)
        event["detail"] = _nested(depth)
    elif how == "huge":
        event["text"] = "z" * draw(st.sampled_from([70_000, 1_000_000]))
    elif how == "nan":
        event["value"] = draw(HOSTILE_FLOATS)
    elif how == "t":
        event["t"] = draw(BAD_T)
    elif how == "kind":
        event["kind"] = draw(st.one_of(ODD, BAD_NAMES))
    elif how == "nonmap":
        event = draw(st.one_of(st.lists(INT, max_size=3), st.text(max_size=8), INT))
    elif how == "garbage":
        return Input("event", MALFORMED, "put", key, draw(st.binary(max_size=64)), note=how)
    elif how == "many_fields":
        event.update({f"f{i}": i for i in range(draw(st.sampled_from([100, 5000])))})
    elif how == "key":
        key = draw(st.sampled_from([f"{ROBOT}/events/a/b", f"{ROBOT}/events/" + "k" * 300]))
        event["blob"] = b"\xff\xfe"
    label = MALFORMED if how in ("t", "kind", "nonmap", "nan") else HOSTILE
    return Input("event", label, "put", key, pack(event), note=how)


# -- commands (Zenoh queries) --------------------------------------------------------------------

def _safe_angle(index: int) -> st.SearchStrategy[float]:
    _, lo, hi = JOINTS[index]
    mid, half = (lo + hi) / 2, (hi - lo) / 4
    return st.integers(-100, 100).map(lambda k: round(mid + half * k / 100, 3))


@st.composite
def valid_command(draw: st.DrawFn) -> tuple[str, dict[str, Any]]:
    """A command that must be accepted (and may run): values well inside every range.
    Stiffness only ever 1.0 and awareness only ever on, so that a limp robot or one
    that stops looking around came from invalid input."""
    verb = draw(st.sampled_from(["say", "behavior/list", "joints/set", "posture", "stiffness", "awareness",
                                 "behavior/stop", "behavior/run", "stop"]))
    if verb == "say":
        args: dict[str, Any] = {"text": f"fuzz {draw(st.integers(0, 10 ** 6))}"}
        if draw(st.booleans()):
            args["volume"] = draw(st.integers(1, 10)) / 10
    elif verb == "joints/set":
        index = draw(st.integers(0, len(JOINTS) - 1))
        args = {"names": [NAMES[index]], "angles": [draw(_safe_angle(index))],
                "speed": draw(st.integers(1, 10)) / 10}
    elif verb == "posture":
        args = {"name": draw(st.sampled_from(["Stand", "StandInit"])), "speed": 0.5}
    elif verb == "stiffness":
        args = {"names": [draw(st.sampled_from(["Body", "Head", "LArm", "HeadYaw"]))], "value": 1.0}
    elif verb == "awareness":
        args = {"enabled": True}
    elif verb == "behavior/run":
        args = {"name": HEY}
    else:
        args = {}
    return verb, args


@st.composite
def invalid_command(draw: st.DrawFn) -> tuple[str, bytes, str]:
    """A command request that must be refused: ``(verb, payload, why)``."""
    verb, args = draw(valid_command().filter(lambda c: c[0] != "stop"))
    how = draw(st.sampled_from(["range", "unknown_name", "nan", "type", "extra", "missing", "nonmap", "garbage",
                                "ext", "bytes", "verb", "long_text", "blank_text"]))
    if how == "verb":
        return draw(st.sampled_from(["dance", "joints", "joints/set/x", "say/", "cmd", "Stop", "stop/now",
                                     "behavior/list/extra", "ç"])), pack(args), how
    if how == "nonmap":
        return verb, pack(draw(st.one_of(st.lists(INT, max_size=3), st.text(max_size=5), INT,
                                         st.floats()))), how
    if how == "garbage":
        return verb, b"\xc1" + draw(st.binary(max_size=40)), how
    if how == "ext":
        return verb, pack({"names": msgpack.ExtType(1, b"x"), "value": 1.0, "text": "a", "name": "b"}), how
    if how == "bytes":
        return verb, pack({"text": b"hello", "name": b"Stand", "names": [b"HeadYaw"], "angles": [0.1],
                           "value": 1.0, "enabled": b"\x01"}), how
    bad = dict(args)
    if how == "extra" or not args:
        bad["bogus"] = draw(ODD)
    elif how == "missing":
        del bad[sorted(bad)[0]]
    elif how == "range":
        if verb == "joints/set":
            _, _, hi = JOINTS[NAMES.index(args["names"][0])]
            choice = draw(st.sampled_from(["angle", "speed0", "speed2"]))
            if choice == "angle":
                bad["angles"] = [hi + draw(st.sampled_from([0.05, 1.0, 100.0]))]
            else:
                bad["speed"] = 0.0 if choice == "speed0" else 2.0
        elif verb == "stiffness":
            bad["value"] = draw(st.sampled_from([-0.5, 1.5, 100.0]))
        elif verb == "say":
            bad["volume"] = draw(st.sampled_from([-1.0, 1.5]))
        elif verb == "posture":
            bad["speed"] = draw(st.sampled_from([0.0, 1.5, -1.0]))
        else:
            bad["bogus"] = 1
    elif how == "unknown_name":
        for field in ("names", "name"):
            if field in bad:
                bad[field] = ["NoSuchJoint"] if field == "names" else "NoSuchThing"
        if not {"names", "name"} & set(bad):
            bad["bogus"] = 1
    elif how == "nan":
        for field in ("angles", "speed", "value", "volume"):
            if field in bad:
                bad[field] = [math.nan] if field == "angles" else draw(st.sampled_from([math.nan, math.inf]))
                break
        else:
            bad["bogus"] = math.nan
    elif how == "type":
        field = sorted(bad)[0]
        bad[field] = draw(st.one_of(st.none(), INT, st.binary(max_size=4),
                                    st.dictionaries(st.text(max_size=2), INT, max_size=1)))
        if field == "text":
            bad[field] = 5
    elif how == "long_text":
        bad = {"text": "w" * 501}
        verb = "say"
    elif how == "blank_text":
        bad = {"text": "   "}
        verb = "say"
    return verb, pack(bad), how


@st.composite
def commands(draw: st.DrawFn) -> Input:
    if draw(st.integers(0, 3)) == 0:
        verb, args = draw(valid_command())
        if verb == "stop" and draw(st.booleans()):  # stop runs whatever it carries
            return Input("command", VALID, "query", f"{ROBOT}/cmd/stop", draw(st.binary(max_size=16)),
                         signature("stop", {}), note="stop with garbage")
        return Input("command", VALID, "query", f"{ROBOT}/cmd/{verb}", pack(args), signature(verb, args))
    verb, payload, why = draw(invalid_command())
    label = HOSTILE if why in ("garbage", "ext", "bytes") else MALFORMED
    return Input("command", label, "query", f"{ROBOT}/cmd/{verb}", payload, note=why)


# -- info ----------------------------------------------------------------------------------

GHOSTS = 6  # robots whose every info reply is garbage


@st.composite
def infos(draw: st.DrawFn) -> Input:
    """Queries on the robot's info keys (valid and garbage), or a frame of a ghost robot
    whose info replies are garbage (the sinks ask for it)."""
    how = draw(st.sampled_from(["query", "query_garbage", "selector", "ghost"]))
    if how == "query":
        key = draw(st.sampled_from([f"{ROBOT}/info", f"{ROBOT}/info/**", f"{ROBOT}/info/derived"]))
        return Input("info", VALID, "query", key, b"")
    if how == "query_garbage":
        return Input("info", MALFORMED, "query", f"{ROBOT}/info",
                     draw(st.one_of(st.binary(max_size=64), st.builds(pack, ODD))), note=how)
    if how == "selector":
        return Input("info", MALFORMED, "query",
                     f"{ROBOT}/info?" + draw(st.sampled_from(["x=1", "_time=[now(-1h)..]", "a;b;c", "%%%", "=" * 50])),
                     b"", note=how)
    ghost = draw(st.integers(0, GHOSTS - 1))
    frame = {"t": time.time(), "seq": draw(st.integers(0, 1000)), "names": ["HeadYaw"], "v": [0.1]}
    return Input("info", HOSTILE, "ghost", f"ghost{ghost}/frame", pack(frame), note=f"ghost{ghost}")


def ghost_reply(index: int) -> bytes:
    """The garbage ``ghost<index>/info`` answers with (one kind per ghost)."""
    replies = [
        pack({"robot": f"ghost{index}", "joints": [{"name": "HeadYaw", "min": math.nan, "max": math.inf}]}),
        pack({"robot": f"ghost{index}", "joints": [{"name": b"HeadYaw", "min": -1, "max": 1}], "rate_hz": "x"}),
        pack([1, 2, 3]),
        b"\xc1\xc1\xc1",
        pack({"robot": f"ghost{index}", "joints": "all", "behaviors": msgpack.ExtType(3, b"q"),
              "derived": [{"key": "*", "min": 1e300, "max": -1e300}]}),
        pack({"robot": f"ghost{index}", "joints": [{"name": "J", "min": 0, "max": 1}] * 5000,
              "blob": "x" * 1_200_000}),
    ]
    return replies[index % len(replies)]


# -- OSC ---------------------------------------------------------------------------------------

def osc_string(text: str | bytes) -> bytes:
    data = (text.encode() if isinstance(text, str) else text) + b"\0"
    return data + b"\0" * (-len(data) % 4)


def osc_message(address: str, *args: Any) -> bytes:
    tags, data = ",", b""
    for arg in args:
        if arg is True or arg is False:
            tags += "T" if arg else "F"
        elif isinstance(arg, int):
            tags, data = tags + "i", data + struct.pack(">i", arg)
        elif isinstance(arg, float):
            tags, data = tags + "f", data + struct.pack(">f", arg)
        else:
            tags, data = tags + "s", data + osc_string(arg)
    return osc_string(address) + osc_string(tags) + data


def osc_bundle(*elements: bytes) -> bytes:
    return b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def _f32(value: float) -> float:
    return struct.unpack(">f", struct.pack(">f", value))[0]


_SIZES = {"i": 4, "f": 4, "c": 4, "r": 4, "m": 4, "h": 8, "d": 8, "t": 8}


def well_formed(data: bytes) -> bool:
    """Whether ``data`` is one OSC message that a strict reader (liblo) would take whole:
    padded strings, the data exactly what the type tags say, nothing after. A message
    without a type tag string counts as well-formed (old senders omit it)."""
    def string(at: int) -> int | None:
        end = data.find(b"\0", at)
        if end < 0:
            return None
        after = end + 1 + (-(end + 1 - at) % 4)
        return after if after <= len(data) and not data[end:after].strip(b"\0") else None

    at = string(0)
    if at is None or not data.startswith(b"/"):
        return False
    if at == len(data):
        return True
    if data[at:at + 1] != b",":
        return False
    tags_end = string(at)
    if tags_end is None:
        return False
    tags = data[at + 1:data.index(b"\0", at)].decode("latin-1")
    at = tags_end
    for tag in tags:
        if tag in _SIZES:
            at += _SIZES[tag]
        elif tag in "sS":
            nxt = string(at)
            if nxt is None:
                return False
            at = nxt
        elif tag == "b":
            if at + 4 > len(data):
                return False
            size = struct.unpack(">i", data[at:at + 4])[0]
            if size < 0:
                return False
            at += 4 + size + (-size % 4)
        elif tag not in "TFNI[]":
            return False
        if at > len(data):
            return False
    return at == len(data)


@st.composite
def valid_osc(draw: st.DrawFn) -> tuple[bytes, str]:
    """A well-formed OSC command and the signature of the request the gateway must make of it."""
    verb, args = draw(valid_command())
    address = f"/{ROBOT}/cmd/{verb}"
    if verb == "say":
        packet = osc_message(address, args["text"], *([args["volume"]] if "volume" in args else []))
        request: dict[str, Any] = {"text": args["text"], **({"volume": _f32(args["volume"])} if "volume" in args
                                                            else {})}
    elif verb == "joints/set":
        packet = osc_message(address, args["names"][0], float(args["angles"][0]), float(args["speed"]))
        request = {"names": args["names"], "angles": [_f32(args["angles"][0])], "speed": _f32(args["speed"])}
    elif verb == "posture":
        packet = osc_message(address, args["name"], 0.5)
        request = {"name": args["name"], "speed": 0.5}
    elif verb == "stiffness":
        packet = osc_message(address, args["names"][0], 1.0)
        request = {"names": args["names"], "value": 1.0}
    elif verb == "awareness":
        packet = osc_message(address, True)
        request = {"enabled": True}
    elif verb == "behavior/run":
        packet = osc_message(address, HEY)
        request = {"name": HEY}
    else:
        packet = osc_message(address)
        request = {}
    return packet, signature(verb, request)


@st.composite
def osc_packets(draw: st.DrawFn) -> Input:
    how = draw(st.sampled_from(["valid", "truncated", "trailing", "overlong", "tags", "noise", "bundle_ok",
                                "bundle_bad", "bundle_nested", "issue_float", "issue_empty", "issue_trailing",
                                "many_args"]))
    key = "osc"
    if how == "valid":
        packet, sig = draw(valid_osc())
        return Input("osc", VALID, "osc", key, packet, sig)
    if how == "bundle_ok":  # a bundle with one broken element: taken whole or not at all, so nothing runs
        packet, sig = draw(valid_osc())
        broken = packet[:-1] if len(packet) % 4 == 0 and len(packet) > 8 else packet + b"\0\0\0\0"
        return Input("osc", MALFORMED, "osc", key, osc_bundle(packet, broken, osc_message("/nobody/cmd/x")), sig,
                     note="bundle with one valid element and one broken")
    packet, _ = draw(valid_osc().filter(lambda p: not p[0].startswith(f"/{ROBOT}/cmd/stop".encode())))
    if how == "truncated":
        data = draw(st.integers(1, len(packet) - 1).map(lambda k: packet[:k]).filter(lambda d: not well_formed(d)))
    elif how == "trailing":
        data = packet + draw(st.binary(min_size=1, max_size=16))
    elif how == "overlong":
        data = packet + b"\0" * draw(st.sampled_from([4, 8, 64]))
    elif how == "tags":
        comma = packet.index(b",")
        rest = packet[comma:][len(osc_string(packet[comma:].split(b"\0", 1)[0])):]
        data = draw(st.text(alphabet="ifsbhdTFN[]cSIxm", min_size=1, max_size=8)
                    .map(lambda tags: packet[:comma] + osc_string("," + tags) + rest)
                    .filter(lambda d: not well_formed(d)))
    elif how == "noise":
        data = draw(st.binary(max_size=200))
    elif how == "bundle_bad":  # a bundle whose sizes lie: nothing in it may run
        inner = osc_message(f"/{ROBOT}/cmd/stiffness", "Body", 0.0)
        size = draw(st.sampled_from([len(inner) + 4, len(inner) - 1, 10 ** 6, -4]))
        data = b"#bundle\0" + struct.pack(">Q", 1) + struct.pack(">i", size) + inner
    elif how == "bundle_nested":
        inner = osc_message(f"/{ROBOT}/cmd/stiffness", "Body", 0.0)[:-2]
        data = osc_bundle(osc_bundle(osc_bundle(inner)), draw(st.binary(max_size=12)))
    elif how == "issue_float":  # issue 13, 1: one byte of a float
        data = osc_string(f"/{ROBOT}/cmd/joints/set") + osc_string(",sf") + osc_string("HeadYaw") + b"\xbd"
    elif how == "issue_empty":  # issue 13, 1: no float bytes at all
        data = osc_string(f"/{ROBOT}/cmd/stiffness") + osc_string(",sf") + osc_string("Body")
    elif how == "issue_trailing":  # issue 13, 1: F and junk
        data = osc_string(f"/{ROBOT}/cmd/awareness") + osc_string(",F") + draw(st.binary(min_size=4, max_size=12))
    else:
        data = osc_message(f"/{ROBOT}/cmd/joints/set", *([0.25] * draw(st.integers(65, 400))))
    label = MALFORMED if how in ("truncated", "trailing", "overlong", "tags", "issue_float", "issue_empty",
                                 "issue_trailing") else HOSTILE
    return Input("osc", label, "osc", key, data, note=how)


def issue_inputs(family: str) -> list[Input]:
    """Issue 13's reproductions, sent as given before each family's generated inputs."""
    now, key = time.time(), f"{ROBOT}/frame"

    def frame(note: str, seq: int, **changes: Any) -> Input:  # each its own seq: no sink takes it for a repeat
        return Input("frame", MALFORMED, "put", key, pack({"t": now, "seq": seq, "names": ["HeadYaw"], "v": [0.1],
                                                          **changes}), note=note)
    fixed = {
        "frame": [frame("issue 3: 1e300", 1, v=[1e300]), frame("issue 5: t an hour ahead", 2, t=now + 3600),
                  frame("issue 2: t 1e12", 3, t=1e12)],
        "event": [Input("event", HOSTILE, "put", f"{ROBOT}/events/behavior",
                        pack({"t": now, "kind": "behavior", "name": b"x"}), note="issue 2: bytes field")],
        "osc": [Input("osc", MALFORMED, "osc", "osc", bytes.fromhex(
                    "2f7065707065722f636d642f6a6f696e74732f73657400002c7366004865616459617700bd"),
                      note="issue 1: one byte of a float"),
                Input("osc", MALFORMED, "osc", "osc", osc_string(f"/{ROBOT}/cmd/stiffness") + osc_string(",sf") +
                      osc_string("Body"), note="issue 1: no float bytes"),
                Input("osc", MALFORMED, "osc", "osc", osc_string(f"/{ROBOT}/cmd/awareness") + osc_string(",F") +
                      b"\x01" * 12, note="issue 1: trailing junk")],
    }
    return fixed.get(family, [])


FAMILIES = {
    "frame": frames,
    "joint": joints,
    "derived": derived,
    "event": events,
    "command": commands,
    "info": infos,
    "osc": osc_packets,
}


@st.composite
def bursts(draw: st.DrawFn) -> tuple[Input, int]:
    """One input of a data or OSC family, to repeat ``count`` times at high rate."""
    family = draw(st.sampled_from(["frame", "joint", "derived", "event", "osc"]))
    item = draw(FAMILIES[family]().filter(lambda i: len(i.payload) < 8192 and i.signature is None))
    return item, draw(st.sampled_from([500, 1000, 2000]))


def flood(count: int = 2000) -> list[Input]:
    """Valid frames of five joints with seqs all over the range, to send as fast as bursts go:
    a robot adapter gone mad, or a script in a loop."""
    names = NAMES[:5]
    return [Input("frame", VALID, "put", f"{ROBOT}/frame",
                  pack({"t": time.time(), "seq": n * 7919 % 2 ** 31, "names": names, "v": [0.1] * 5}),
                  note="flood of valid frames") for n in range(count)]


class Oracle:
    """Which commands could run: each valid command sent adds its signature; each
    ``command`` event with ``ok = true`` takes one away, or is executed from invalid input."""

    def __init__(self) -> None:
        self.allowed: Counter[str] = Counter()
        self.sent_valid: Counter[str] = Counter()
        self.executed: Counter[str] = Counter()
        self.unexpected: list[dict[str, Any]] = []

    def sent(self, item: Input) -> None:
        if item.signature is not None:
            self.allowed[item.signature] += 1
            self.sent_valid[item.family] += 1

    def event(self, event: dict[str, Any]) -> None:
        if event.get("ok") is not True:
            return
        sig = signature(str(event.get("verb")), event.get("args", {}))
        self.executed[str(event.get("verb"))] += 1
        if self.allowed[sig] > 0:
            self.allowed[sig] -= 1
        else:
            self.unexpected.append(event)
