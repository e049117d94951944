"""The sink's hand-written OSC encoder against python-osc, the independent reference:
the same bytes as python-osc's builders, and python-osc's parser reads back the same values."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.parsing import osc_types

from sonibus.adapters.osc import encode
from sonibus.adapters.osc.config import Target
from sonibus.adapters.osc.encode import Double
from sonibus.adapters.osc.profiles import PepperOscProfile, SonibusProfile
from sonibus.bus.keys import Key

settings.register_profile("osc", deadline=None)
settings.load_profile("osc")

FLOAT32_MAX = float(np.finfo(np.float32).max)
LAST_NTP_ERA_S = 2**32 - encode.NTP_OFFSET - 1  # 2036-02-07: the last second an era-0 timetag holds

# OSC strings are NUL-terminated, so they hold any character but NUL.
TEXT = st.text(st.characters(codec="utf-8", exclude_characters="\0"), max_size=40)
# Address parts: any character but NUL and those OSC reserves for patterns (space # * , / ? [ ] { }).
PART = st.text(st.characters(codec="utf-8", exclude_characters="\0 #*,/?[]{}"), min_size=1, max_size=12)
ADDRESS = st.lists(PART, min_size=1, max_size=5).map(lambda parts: "/" + "/".join(parts))
INT32 = st.integers(-(2**31), 2**31 - 1)
FLOAT32 = st.floats(width=32)                  # exact float32 values, ±inf and nan included
IN_RANGE = st.floats(-FLOAT32_MAX, FLOAT32_MAX)  # doubles that round to a finite float32
ARG = st.one_of(FLOAT32, IN_RANGE, INT32, TEXT, st.booleans(), st.floats().map(Double))


def reference(address: str, args) -> bytes:
    """The message as python-osc builds it, each argument given its type explicitly."""
    builder = OscMessageBuilder(address)
    for arg in args:
        if isinstance(arg, bool):
            builder.add_arg(arg)  # T / F
        elif isinstance(arg, int):
            builder.add_arg(arg, "i")
        elif isinstance(arg, Double):
            builder.add_arg(float(arg), "d")
        elif isinstance(arg, float):
            builder.add_arg(arg, "f")
        else:
            builder.add_arg(arg, "s")
    return builder.build().dgram


def as_sent(arg):
    """What a receiver reads back: floats rounded to float32, Double and the rest unchanged."""
    if isinstance(arg, float) and not isinstance(arg, Double):
        return float(np.float32(arg))
    return arg


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return type(a) is type(b) and a == b


def assert_reads_back(dgram: bytes, address: str, args) -> None:
    parsed = OscMessage(dgram)
    assert parsed.address == address
    assert len(parsed.params) == len(args)
    for got, arg in zip(parsed.params, args, strict=True):
        assert same(got, float(as_sent(arg)) if isinstance(arg, float) else as_sent(arg)), (got, arg)


@given(ADDRESS, st.lists(ARG, max_size=8))
@example("/pepperdata", ["/HeadYaw", "/PositionSensor", 0.25])
@example("/pepper/joints/HeadYaw", [])
@example("/a", ["", "abc", "abcd", 1, -(2**31), 2**31 - 1, True, False, Double(1e300)])
def test_message_is_what_python_osc_builds_and_reads(address, args):
    dgram = encode.message(address, *args)
    assert dgram == reference(address, args)
    assert len(dgram) % 4 == 0
    assert_reads_back(dgram, address, args)


@given(ADDRESS, st.lists(st.one_of(FLOAT32, IN_RANGE), max_size=20))
@example("/pepper/derived/hand/RHand", [0.1, 0.2, 0.3])
@example("/x", [math.inf, -math.inf, math.nan, -0.0, 1e-45, FLOAT32_MAX])
def test_floats_is_message_of_floats(address, values):
    dgram = encode.floats(address, values)
    assert dgram == encode.message(address, *values) == reference(address, values)
    assert_reads_back(dgram, address, values)


@given(st.floats(allow_nan=False).filter(lambda x: abs(x) > FLOAT32_MAX))
@example(1e300)
@example(-1e39)
def test_a_float_beyond_float32_is_infinite_or_refused(value):
    """Rounded to float32 it is ±inf; the encoder sends that or raises — never something else."""
    for build in (lambda: encode.message("/x", value), lambda: encode.floats("/x", [value])):
        try:
            dgram = build()
        except encode.EncodeError:
            continue
        assert OscMessage(dgram).params == [math.copysign(math.inf, value)]


@given(st.one_of(st.integers(max_value=-(2**31) - 1), st.integers(min_value=2**31)))
def test_an_int_beyond_int32_is_refused(value):
    with pytest.raises(encode.EncodeError, match="'/x': "):
        encode.message("/x", value)


@pytest.mark.parametrize("arg", [None, b"blob", [1.0], {"v": 1}])
def test_other_types_are_refused(arg):
    with pytest.raises(encode.EncodeError, match="cannot send"):
        encode.message("/x", arg)


def test_a_string_with_nul_is_refused_or_read_back_whole():
    """OSC strings end at the first NUL: "a\\0bcdefg" sent as is would make a receiver read
    "a", then "defg" as the next argument. Refuse it, or send something that reads back aligned."""
    try:
        dgram = encode.message("/pepper/events/speech", "a\0bcdefg", "started")
    except encode.EncodeError:
        return
    params = OscMessage(dgram).params
    assert len(params) == 2 and params[1] == "started", f"misaligned: {params}"


@given(st.floats(1.0, LAST_NTP_ERA_S))
@example(1.0)
@example(1_700_000_000.123456)
@example(LAST_NTP_ERA_S + 0.999)
def test_timetag_is_read_back_by_python_osc_within_a_microsecond(t):
    tag = encode.timetag(t)
    assert 0 <= tag < 2**64
    dgram = encode.bundle(tag, [])
    assert abs(OscBundle(dgram).timestamp - t) <= 1e-6
    # python-osc's own conversion of the same UNIX time gives the very same 64 bits.
    assert dgram[8:16] == osc_types.write_date(t)


def test_immediately_is_the_osc_special_timetag():
    assert encode.bundle(encode.IMMEDIATELY, []) == OscBundleBuilder(osc_types.IMMEDIATELY).build().dgram
    assert OscBundle(encode.bundle(encode.IMMEDIATELY, [])).timestamp == osc_types.IMMEDIATELY


@given(st.floats(1.0, LAST_NTP_ERA_S), st.lists(st.tuples(ADDRESS, st.lists(ARG, max_size=4)), max_size=6))
def test_bundle_is_what_python_osc_builds_and_reads(t, messages):
    dgram = encode.bundle(encode.timetag(t), [encode.message(a, *args) for a, args in messages])
    builder = OscBundleBuilder(t)
    for address, args in messages:
        builder.add_content(OscMessage(reference(address, args)))
    assert dgram == builder.build().dgram
    parsed = OscBundle(dgram)
    assert parsed.num_contents == len(messages)
    for content, (address, args) in zip(parsed, messages, strict=True):
        assert_reads_back(content.dgram, address, args)


def test_bundle_layout():
    """``#bundle``, NUL, 64-bit timetag, then per element its int32 size and its bytes; bundles nest."""
    first = encode.message("/pepper/joints/HeadYaw", 0.5)
    second = encode.message("/pepper/events/behavior", "x", "started")
    inner = encode.bundle(encode.IMMEDIATELY, [second])
    tag = encode.timetag(1_700_000_000.5)
    dgram = encode.bundle(tag, [first, inner])
    assert dgram[:8] == b"#bundle\0"
    assert struct.unpack(">Q", dgram[8:16]) == (tag,)
    assert tag == ((1_700_000_000 + 2_208_988_800) << 32) | 2**31
    offset, elements = 16, []
    while offset < len(dgram):
        (size,) = struct.unpack(">i", dgram[offset:offset + 4])
        assert size % 4 == 0
        elements.append(dgram[offset + 4:offset + 4 + size])
        offset += 4 + size
    assert offset == len(dgram) and elements == [first, inner]
    parsed = OscBundle(dgram)
    assert parsed.timestamp == pytest.approx(1_700_000_000.5, abs=1e-6)
    assert parsed.content(0).params == [0.5]
    assert isinstance(parsed.content(1), OscBundle) and parsed.content(1).content(0).params == ["x", "started"]
    assert encode.bundle(tag, []) == dgram[:16]


# -- one element OSC cannot carry: left out, the rest sent ---------------------------------

T = 1_700_000_000.25
GOOD = [(Key.parse("pepper/joints/HeadYaw"), (0.25,)), (Key.parse("pepper/derived/hand/R"), (0.1, 0.2, 0.3))]
BAD = (Key.parse("pepper/joints/HeadPitch"), (1e300,))


@pytest.mark.parametrize("bundle", [False, True], ids=["messages", "bundle"])
def test_a_frame_leaves_out_just_the_message_osc_cannot_carry(bundle):
    profile = SonibusProfile(Target(to="127.0.0.1:9", bundle=bundle))
    datagrams, dropped = profile.frame("pepper", T, 7, [GOOD[0], BAD, GOOD[1]], 0.01)
    [error] = dropped
    assert isinstance(error, encode.EncodeError) and "'/pepper/joints/HeadPitch'" in str(error)
    messages = [reference("/pepper/joints/HeadYaw", [0.25]), reference("/pepper/derived/hand/R", [0.1, 0.2, 0.3])]
    if not bundle:
        assert datagrams == messages
        return
    builder = OscBundleBuilder(T)
    for message in messages:
        builder.add_content(OscMessage(message))
    assert datagrams == [builder.build().dgram]


def test_pepperosc_leaves_out_just_the_joint_osc_cannot_carry():
    profile = PepperOscProfile(Target(to="127.0.0.1:9", profile="pepperosc"))
    datagrams, dropped = profile.frame("pepper", T, 7, [BAD, GOOD[0]], 0.02)
    assert len(dropped) == 1
    assert datagrams == [reference("/pepperdata", ["/HeadYaw", "/PositionSensor", 0.25]),
                         reference("/pepperdata", ["/latency", 0.02])]


def test_a_frame_of_nothing_but_bad_values_sends_nothing():
    profile = SonibusProfile(Target(to="127.0.0.1:9", bundle=True))
    datagrams, dropped = profile.frame("pepper", T, 7, [BAD, BAD], 0.01)
    assert datagrams == [] and len(dropped) == 2


@pytest.mark.parametrize("fields", [{"text": "a\0b", "state": "started"}, {"text": "\ud800", "state": "done"}],
                         ids=["nul", "lone-surrogate"])
def test_an_event_osc_cannot_carry_is_refused_with_its_address(fields):
    profile = SonibusProfile(Target(to="127.0.0.1:9"))
    with pytest.raises(encode.EncodeError, match="'/pepper/events/speech'"):
        profile.event("pepper", "speech", {"t": T, "kind": "speech", **fields})
