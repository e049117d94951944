"""A robot's frames read back from their bytes (``codec.FrameDecoder``, ``Gate.known_frame``,
``Selection._steady``: issue 35) against msgpack and the gate's general way: whatever the
bytes, the lane reads what ``unpackb`` and the gate read, or nothing (None), and then the
general way takes them, and says what is wrong with them."""

from __future__ import annotations

import math
import random
import time

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sonibus.bus import codec
from sonibus.bus.keys import Key
from sonibus.bus.messages import MAX_SEQ, MAX_VALUE, BadMessage, Gate
from sonibus.bus.streams import Selection
from sonibus.bus.verdicts import VERDICTS

NAMES = ("HeadYaw", "HeadPitch", "LShoulderPitch")
KEY = Key.parse("pepper/frame")
NOW = time.time()  # (the frames drawn from a fixed range: hypothesis draws again the same way)

floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0, MAX_VALUE, 1e300]))
values = st.one_of(floats, st.integers(-2**63, 2**64 - 1), st.booleans(), st.none(), st.text(max_size=3))
seqs = st.one_of(st.sampled_from([0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, MAX_SEQ, MAX_SEQ + 1,
                                  2**64 - 1, -1, -129]), st.integers(-2**63, 2**64 - 1))


@st.composite
def frames(draw: st.DrawFn) -> bytes:
    """msgpack bytes of frames: mostly of NAMES and floats as a robot's, some of everything else
    (ints, bools, NaN, other names, a field more or fewer, another order, float32, bytes changed)."""
    names = list(NAMES) if draw(st.integers(0, 4)) else draw(st.lists(st.sampled_from(
        ["HeadYaw", "HeadPitch", "LShoulderPitch", "HeadYax", "X" * 32]), max_size=4))
    usual = draw(st.booleans())
    frame = {"t": draw(st.one_of(st.floats(0, NOW), floats, st.integers(0, 10))),
             "seq": draw(seqs),
             "names": names,
             "v": [draw(st.floats(-3, 3) if usual else values) for _ in names]}
    if not draw(st.integers(0, 5)):
        frame["v"] = frame["v"][:-1] if frame["v"] and draw(st.booleans()) else [*frame["v"], 0.5]
    if not draw(st.integers(0, 5)):
        frame["velocity"] = [0.0] * len(names)
    if not draw(st.integers(0, 5)):
        del frame[draw(st.sampled_from(list(frame)))]
    if not draw(st.integers(0, 5)):
        frame = dict(reversed(list(frame.items())))
    try:
        payload = msgpack.packb(frame, use_bin_type=True, use_single_float=not draw(st.integers(0, 8)))
    except OverflowError:  # (a float32 cannot hold it)
        payload = msgpack.packb(frame, use_bin_type=True)
    if payload and not draw(st.integers(0, 4)):  # a byte changed, some cut off, or some more
        at = draw(st.integers(0, len(payload) - 1))
        how = draw(st.sampled_from(["flip", "cut", "more"]))
        if how == "flip":
            payload = payload[:at] + bytes([payload[at] ^ draw(st.integers(1, 255))]) + payload[at + 1:]
        else:
            payload = payload[:at] if how == "cut" else payload + payload[at:at + 9]
    return payload


def msgpack_reads(payload: bytes) -> dict | None:
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return None


@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames())
def test_the_decoder_reads_what_msgpack_reads_or_nothing(payload):
    read = codec.FrameDecoder(NAMES).decode(payload)
    if read is None:
        return
    message = msgpack_reads(payload)
    assert message is not None and list(message) == ["t", "seq", "names", "v"], message
    assert tuple(message["names"]) == NAMES
    t, seq, values = read
    assert (t, seq, values) == (message["t"], message["seq"], tuple(message["v"])) or math.isnan(t) \
        or any(math.isnan(v) for v in values)  # (NaN is not equal to itself: compared as bytes below)
    assert msgpack.packb((t, seq, values)) == msgpack.packb((message["t"], message["seq"], message["v"]))
    assert t.__class__ is float and seq.__class__ is int and all(v.__class__ is float for v in values)


@pytest.mark.parametrize("joints", [0, 1, 15, 16, 17, 26, 70000])
def test_every_frame_the_encoder_writes_of_floats_is_read_back(joints):
    """Array headers (fix, 16-bit, 32-bit), names short and long, each width of a seq."""
    rng = random.Random(joints)
    names = tuple(("J" * rng.choice((1, 5, 31, 32, 40))) + str(j) for j in range(joints))
    encoder, decoder = codec.FrameEncoder(names), codec.FrameDecoder(names)
    for seq in (0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1):
        values = [rng.uniform(-10, 10) for _ in range(joints)]
        t = time.time() + rng.random()
        assert decoder.decode(encoder.encode(t, seq, values)) == (t, seq, tuple(values)), seq
    big = codec.encode({"t": 1.5, "seq": 2**40, "names": list(names), "v": [0.5] * joints})  # (as msgpack packs it)
    assert decoder.decode(big) == (1.5, 2**40, (0.5,) * joints)


def known_gate() -> Gate:
    """A gate that knows pepper's NAMES: a frame of them checked, and a second one read by its lane."""
    gate, encoder = Gate(), codec.FrameEncoder(NAMES)
    gate.verdict(KEY, encoder.encode(1.0, 1, [0.0] * len(NAMES)))
    assert gate.known_frame(KEY, encoder.encode(1.0, 2, [0.0] * len(NAMES))) is None  # (the names' first frame)
    assert gate.known_frame(KEY, encoder.encode(1.0, 3, [0.0] * len(NAMES))) is not None
    return gate


def general(gate: Gate, payload: bytes) -> tuple[dict, tuple[str, ...]] | str:
    try:
        return gate.verdict(KEY, payload)
    except BadMessage as exc:
        return str(exc)


@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames())
def test_the_gates_lane_lets_through_only_what_its_general_way_does_and_as_it_does(payload):
    gate = known_gate()
    known = gate.known_frame(KEY, payload)
    verdict = general(gate, payload)
    if known is None:
        return  # (the general way takes it: a frame it lets through, or a reason)
    assert not isinstance(verdict, str), verdict
    message, names = verdict
    t, seq, values, known_names = known
    assert known_names is names and names == NAMES
    assert (t, seq, values) == (message["t"], message["seq"], tuple(message["v"]))


def test_the_gates_lane_refuses_what_is_out_of_bounds_and_the_general_way_says_why():
    gate, encoder = known_gate(), codec.FrameEncoder(NAMES)
    assert gate.known_frame(KEY, encoder.encode(1.5, 2, [0.1, 0.2, 0.3]))[:3] == (1.5, 2, (0.1, 0.2, 0.3))
    for t, seq, v, reason in [
            (time.time() + 3600, 3, 0.1, "not a time"), (-1.0, 3, 0.1, "not a time"), (1.5, 3, math.nan, "v[0]"),
            (1.5, 3, 2 * MAX_VALUE, "outside"), (1.5, 3, math.inf, "v[0]")]:
        payload = codec.encode({"t": t, "seq": seq, "names": list(NAMES), "v": [v, 0.2, 0.3]})
        assert gate.known_frame(KEY, payload) is None
        assert reason in general(gate, payload)
    payload = codec.encode({"t": 1.5, "seq": MAX_SEQ + 1, "names": list(NAMES), "v": [0.1, 0.2, 0.3]})
    assert gate.known_frame(KEY, payload) is None and "seq" in general(gate, payload)
    assert Gate().known_frame(KEY, encoder.encode(1.5, 2, [0.1, 0.2, 0.3])) is None  # (names not checked yet)


def test_a_robot_whose_names_change_every_frame_makes_no_decoder():
    """Two publishers of one robot name, or a fuzzer: each frame's names differ from the last
    one's, and the gate makes a decoder only for names that held over a frame."""
    gate, other = known_gate(), ("HeadYaw", "HeadPitch")
    made: list[tuple[str, ...]] = []
    real = codec.FrameDecoder.__init__

    def counted(self, names):
        made.append(names)
        real(self, names)

    import sonibus.bus.messages as messages_module
    messages_module.FrameDecoder.__init__ = counted
    try:
        for seq in range(4, 40):
            names = NAMES if seq % 2 else other
            payload = codec.FrameEncoder(names).encode(1.0, seq, [0.0] * len(names))
            assert gate.known_frame(KEY, payload) is None
            assert gate.verdict(KEY, payload)[1] == names
        assert made == []
        for seq in (40, 41):  # (the same names over a frame: made at the next)
            payload = codec.FrameEncoder(other).encode(1.0, seq, [0.0, 0.0])
            assert gate.known_frame(KEY, payload) is None and gate.verdict(KEY, payload)[1] == other
        payload = codec.FrameEncoder(other).encode(1.0, 42, [0.0, 0.0])
        assert gate.known_frame(KEY, payload) is not None and made == [other]
    finally:
        messages_module.FrameDecoder.__init__ = real


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames(), min_size=1, max_size=6))
def test_the_selections_lane_gives_what_incoming_gives(payloads):
    """Two selections of the same patterns take the same frames, one by its lane first."""
    lane, way = Selection(["pepper/joints/Head*"]), Selection(["pepper/joints/Head*"])
    takers = VERDICTS.takers
    VERDICTS.takers = 1  # (each as the one taker of its process, as an OSC node alone is: its lane open)
    try:
        taken_alike(lane, way, payloads)
    finally:
        VERDICTS.takers = takers


def taken_alike(lane: Selection, way: Selection, payloads: list[bytes]) -> None:
    first = codec.FrameEncoder(NAMES).encode(1.0, 1, [0.0] * 3)
    for selection in (lane, way):
        selection.incoming("pepper/frame", first)
    assert lane._steady("pepper/frame", first) is not None  # (by the one-pass way: the byte lane's decoder comes next)
    for payload in payloads:
        steady = lane._steady("pepper/frame", payload)
        try:
            expected = way.incoming("pepper/frame", payload)
        except BadMessage:
            assert steady is None
            continue
        if steady is None:
            lane.incoming("pepper/frame", payload)  # (as Streams.take does then: the two keep the same state)
            continue
        assert steady.message == expected.message or math.isnan(steady.t)
        assert (steady.t, steady.seq, steady.values) == (expected.t, expected.seq, expected.values)
        assert steady.selected.keys == expected.selected.keys
        assert steady.event is None and steady.parts is None
