"""The message layer's gate: every section refuses what it must, in one line, and
agrees with the schemas it reads its bounds from."""

from __future__ import annotations

import time

import jsonschema
import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus import schemas
from sonibus.bus import framing, messages
from sonibus.bus.keys import Key
from sonibus.bus.messages import BadMessage, Gate, Limits

FRAME, SAMPLE, DERIVED, EVENT = (Key.parse(k) for k in ("pepper/frame", "pepper/joints/HeadYaw",
                                                         "pepper/derived/velocity/HeadYaw", "pepper/events/behavior"))


def pack(message: object) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


def refused(key: Key, message: object, gate: Gate | None = None) -> str:
    with pytest.raises(BadMessage) as caught:
        (gate or Gate()).check(key, message if isinstance(message, bytes) else pack(message))
    reason = str(caught.value)
    assert reason and "\n" not in reason and len(reason) < 200, reason
    return reason


def now_frame(**changes: object) -> dict:
    return {**framing.frame(time.time(), 1, ["HeadYaw", "HeadPitch"], [0.1, -0.2]), **changes}


def test_a_good_message_of_each_section_passes_unchanged():
    gate, t = Gate(), time.time()
    for key, message in [(FRAME, now_frame(cmd=[0.0, 0.1])), (SAMPLE, {"t": t, "seq": 3, "v": 0.5, "temp": 40}),
                         (DERIVED, {"t": t, "seq": 3, "v": [0.1, 0.2, 0.3]}),
                         (EVENT, {"t": t, "kind": "behavior", "name": "x", "state": "started", "extra": {"a": [1]}}),
                         (Key.parse("pepper/cmd/say"), {"text": "hello"}), (Key.parse("pepper/cmd/stop"), {})]:
        assert gate.check(key, pack(message)) == message


@pytest.mark.parametrize(("message", "reason"), [
    (now_frame(v=[1e300, 0.0]), "v[0] = 1e+300 is outside ±1e+06"),
    (now_frame(v=[float("nan"), 0.0]), "v[0] = nan is outside ±1e+06"),
    (now_frame(v=[0.0, float("-inf")]), "v[1] = -inf is outside ±1e+06"),
    (now_frame(v=[0.0, "1"]), "v[1] = '1' is not a number"),
    (now_frame(v=[0.0, True]), "v[1] = True is not a number"),
    (now_frame(v=[0.1]), "names and v are not two lists of the same length"),
    (now_frame(names=["HeadYaw", "HeadYaw"]), "joint names are not unique"),
    (now_frame(names=["HeadYaw", "a/b"]), "joint name 'a/b' is not one plain key chunk"),
    (now_frame(names=["HeadYaw", "*"]), "joint name '*' is not one plain key chunk"),
    (now_frame(names=["HeadYaw", 7]), "joint name 7 is not one plain key chunk"),
    (now_frame(t=time.time() + 3600), "is not a time between 1970 and 5 s from now"),
    (now_frame(t=float("nan")), "t = nan is not a time"),
    (now_frame(t=-1.0), "t = -1.0 is not a time"),
    (now_frame(t="now"), "t = 'now' is not a number"),
    (now_frame(seq=-1), "seq = -1 is not an integer in 0.."),
    (now_frame(seq=1.5), "seq = 1.5 is not an integer"),
    (now_frame(cmd=[0.1]), "cmd is not a list of 2 numbers"),
    (now_frame(cmd=[0.1, b"x"]), "cmd[1] = b'x' is not a number"),
    ({"t": time.time(), "seq": 1, "names": ["HeadYaw"]}, "no 'v'"),
    ([1, 2], "payload is a msgpack list, expected a map"),
])
def test_bad_frames_are_refused_saying_why(message, reason):
    assert reason in refused(FRAME, message)


def test_a_frame_of_50000_made_up_joints_is_refused_before_its_names_are_looked_at():
    names = [f"J{i}" for i in range(50_000)]
    reason = refused(FRAME, now_frame(names=names, v=[0.0] * len(names)))
    assert reason.startswith("payload of ") and reason.endswith(" bytes is over the limit of 65536"), reason
    small = [f"J{i}" for i in range(messages.MAX_JOINTS + 1)]
    assert refused(FRAME, now_frame(names=small, v=[0.0] * len(small))) == "129 joints in one frame, at most 128"


def test_the_clock_skew_tolerance_is_configurable():
    ahead = now_frame(t=time.time() + 30)
    assert "30 s" not in refused(FRAME, ahead)
    assert Gate(Limits(max_future_s=60)).check(FRAME, pack(ahead)) == ahead


@pytest.mark.parametrize(("message", "reason"), [
    ({"t": 1.0, "kind": "behavior", "name": b"x"}, "event.name: bytes b'x' cannot be carried"),
    ({"t": 1.0, "kind": "behavior", "name": msgpack.ExtType(5, b"ab")}, "ExtType"),
    ({"t": 1.0, "kind": "behavior", "v": float("nan")}, "event.v: nan is not a finite number"),
    ({"t": 1.0, "kind": "behavior", 3: "a"}, "event: key 3 is not a string"),
    ({"t": 1.0, "kind": "behavior", "deep": [[[[[[[[["too deep"]]]]]]]]]}, "nested deeper than 8"),
    ({"t": 1.0, "kind": ""}, "kind = '' is not a non-empty string"),
    ({"t": 1.0}, "no 'kind'"),
    ({"t": 1.0, "kind": "behavior", "text": "a" * 70_000}, "over the limit of 65536"),
])
def test_bad_events_are_refused_saying_why(message, reason):
    assert reason in refused(EVENT, message)


def test_samples_and_derived_values_are_checked_like_frames():
    t = time.time()
    assert refused(SAMPLE, {"t": t, "seq": 0, "v": 1e300}) == "v[0] = 1e+300 is outside ±1e+06"
    assert "no 'v'" in refused(SAMPLE, {"t": t, "seq": 0})
    assert "field 'a/b' is not a plain name" in refused(SAMPLE, {"t": t, "seq": 0, "v": 0.1, "a/b": 1.0})
    assert "v holds 0 numbers" in refused(DERIVED, {"t": t, "seq": 0, "v": []})
    assert "v[2] = 'z' is not a number" in refused(DERIVED, {"t": t, "seq": 0, "v": [0.1, 0.2, "z"]})
    assert "is outside" in refused(DERIVED, {"t": t, "seq": 0, "v": [0.1, 1e7]})


def test_robot_info_is_checked_against_its_schema_and_its_limits():
    info_key, derived_key = Key.parse("pepper/info"), Key.parse("pepper/info/derived")
    assert "not a valid robot info: 'model' is a required property" in refused(info_key, {"robot": "pepper"})
    assert "not a valid derived info" in refused(derived_key, {"robot": "pepper", "derived": "no"})
    assert "bytes" in refused(info_key, {"robot": b"pepper"})


def test_a_key_outside_the_sections_is_refused():
    assert refused(Key.parse("pepper/video/cam"), {}).startswith("'video' is not a section of the key space")


def test_a_payload_that_is_not_msgpack_is_refused():
    assert refused(FRAME, b"\xc1 not msgpack").startswith("payload is not msgpack")


# -- the gate and the schemas agree ----------------------------------------------------------

NAMES = st.sampled_from(["HeadYaw", "HeadPitch", "LHand", "a/b", "R*", "x y", "", "$"])
NUMBERS = st.one_of(st.floats(allow_nan=False, min_value=-2e6, max_value=2e6), st.integers(-10**7, 10**7),
                    st.just(float("inf")), st.booleans(), st.text(max_size=2), st.none())
TIMES = st.one_of(st.floats(min_value=-10, max_value=time.time() - 60, allow_nan=False), st.text(max_size=2))
SEQS = st.one_of(st.integers(-5, 2**64 - 1), st.text(max_size=2), st.none())


@st.composite
def frames(draw: st.DrawFn) -> dict:
    names = draw(st.lists(NAMES, max_size=6))
    size = st.just(len(names))
    message = {"t": draw(TIMES), "seq": draw(SEQS), "names": names,
               "v": draw(st.lists(NUMBERS, min_size=len(names), max_size=len(names)))}
    if draw(st.booleans()):
        message[draw(st.sampled_from(["cmd", "temp", "a/b"]))] = draw(
            size.flatmap(lambda n: st.lists(NUMBERS, min_size=n, max_size=n)))
    return message


@given(frames())
@settings(max_examples=400, deadline=None)
def test_the_gate_accepts_a_frame_exactly_when_the_schema_does(frame):
    try:
        Gate().check(FRAME, pack(frame))
        accepted = True
    except BadMessage:
        accepted = False
    schema_ok = schemas.validator("frame").is_valid(frame)
    assert accepted == schema_ok, (frame, next(schemas.validator("frame").iter_errors(frame), None))


DERIVED_NAMES = st.sampled_from(["qom/Body", "hand/R", "velocity/HeadYaw", "a/b/c", "qom", "qom/", "/x", "a/*",
                                 "x y/z", 7])
DERIVED_VALUES = st.one_of(NUMBERS, st.lists(NUMBERS, max_size=3), st.lists(st.floats(-1.0, 1.0), min_size=60,
                                                                             max_size=70))


@st.composite
def derived_frames(draw: st.DrawFn) -> dict:
    names = draw(st.lists(DERIVED_NAMES, max_size=5))  # (v as long: a schema cannot say "as many as names")
    message = {"t": draw(TIMES), "seq": draw(SEQS), "names": names,
               "v": draw(st.lists(DERIVED_VALUES, min_size=len(names), max_size=len(names)))}
    if not draw(st.integers(0, 9)):
        message[draw(st.sampled_from(["cmd", "x"]))] = 0.5
    return message


@given(derived_frames())
@settings(max_examples=400, deadline=None)
def test_the_gate_accepts_a_derived_frame_exactly_when_the_schema_does(frame):
    key = Key.parse("pepper/derived")
    gate = Gate()
    for _ in range(2):  # (the second time: its names remembered from the first check)
        try:
            gate.check(key, pack(frame))
            accepted = True
        except BadMessage:
            accepted = False
        assert accepted == schemas.validator("derived_frame").is_valid(frame), (
            frame, next(schemas.validator("derived_frame").iter_errors(frame), None))


def test_a_derived_frame_whose_names_and_values_differ_in_length_is_refused():
    frame = framing.derived_frame(time.time(), 1, ["qom/Body", "hand/R"], [0.5])
    assert "names and v are not two lists of the same length" in refused(Key.parse("pepper/derived"), frame)


@st.composite
def streams(draw: st.DrawFn) -> list[tuple[str, dict]]:
    """Frames of two robots whose joint names come from a few lists, good and bad."""
    lists = draw(st.lists(st.lists(NAMES, max_size=4), min_size=1, max_size=3))
    out = []
    for _ in range(draw(st.integers(1, 8))):
        names = list(draw(st.sampled_from(lists)))
        values = draw(st.lists(st.one_of(st.floats(-1.0, 1.0), NUMBERS), min_size=len(names), max_size=len(names)))
        out.append((draw(st.sampled_from(["pepper", "nao"])), now_frame(names=names, v=values)))
    return out


@given(streams())
@settings(max_examples=300, deadline=None)
def test_one_gate_over_many_frames_accepts_each_exactly_when_the_schema_does(sequence):
    """A node's gate remembers each robot's last joint names and the lists it checked: what
    it remembers never lets through a frame the schema refuses (nor refuses one it takes)."""
    gate = Gate()
    for robot, frame in sequence:
        try:
            gate.check(Key.parse(f"{robot}/frame"), pack(frame))
            accepted = True
        except BadMessage:
            accepted = False
        assert accepted == schemas.validator("frame").is_valid(frame), (robot, frame)


MAX = messages.MAX_VALUE
VALUES = st.lists(st.one_of(st.floats(), st.floats(-2 * MAX, 2 * MAX), st.sampled_from([MAX, -MAX, MAX / 2, 0.0, -0.0]),
                            st.integers(-10**20, 10**20), st.booleans(), st.text(max_size=2), st.none(),
                            st.just([0.5]), st.just({"v": 0.5})), max_size=40)


@given(st.one_of(VALUES, st.lists(st.floats(-MAX, MAX), max_size=128)))
@settings(max_examples=1000, deadline=None)
def test_the_quick_check_of_values_lets_through_only_what_the_value_by_value_check_does(values):
    """``plain_floats`` (two C loops) says yes only to values each of which is a finite
    number within ±MAX_VALUE and no bool; ``numbers`` refuses exactly the others."""
    one_by_one = all(isinstance(v, int | float) and not isinstance(v, bool) and -MAX <= v <= MAX for v in values)
    if messages.plain_floats(values):
        assert one_by_one, values
    try:
        messages.numbers(values, "v")
        accepted = True
    except BadMessage:
        accepted = False
    assert accepted == one_by_one, values


def test_a_checked_frame_whose_names_are_changed_afterwards_lets_nothing_through():
    """The gate remembers a robot's names from a copy: a node that changes the list of a
    message it was given does not make the gate take a bad one for it."""
    gate = Gate()
    checked = gate.check(FRAME, pack(now_frame()))
    checked["names"][1] = "a/b"
    assert "joint name 'a/b' is not one plain key chunk" in refused(FRAME, now_frame(names=["HeadYaw", "a/b"]), gate)
    assert gate.check(FRAME, pack(now_frame()))["names"] == ["HeadYaw", "HeadPitch"]


@given(st.fixed_dictionaries({"t": TIMES, "seq": SEQS, "v": NUMBERS},
                             optional={"cmd": NUMBERS, "a b": NUMBERS, "temp": NUMBERS}))
@settings(max_examples=300, deadline=None)
def test_the_gate_accepts_a_sample_exactly_when_the_schema_does(sample):
    for key, name in ((SAMPLE, "joint_sample"), (DERIVED, "derived_sample")):
        try:
            Gate().check(key, pack(sample))
            accepted = True
        except BadMessage:
            accepted = False
        assert accepted == schemas.validator(name).is_valid(sample), (name, sample)


def test_the_schemas_hold_the_bounds_the_gate_uses():
    frame = schemas.load("frame")["properties"]
    assert frame["names"]["maxItems"] == messages.MAX_JOINTS and frame["names"]["uniqueItems"] is True
    for name in ("frame", "joint_sample", "derived_sample"):
        with pytest.raises(jsonschema.ValidationError):
            schemas.validate(name, {"t": 1.0, "seq": 0, "names": ["a"], "v": 2e6 if name != "frame" else [2e6]})


def test_an_owner_leaves_out_the_joints_a_glitching_sensor_reports_and_keeps_the_rest():
    glitch = framing.frame(time.time(), 4, ["HeadYaw", "HeadPitch", "LHand"], [0.1, float("nan"), 0.5],
                            {"temp": [40.0, 41.0, float("inf")]})
    kept, left_out = framing.valid_part(glitch)
    assert left_out == ["HeadPitch", "LHand"]
    assert kept == {"t": glitch["t"], "seq": 4, "names": ["HeadYaw"], "v": [0.1], "temp": [40.0]}
    assert Gate().check(FRAME, pack(kept)) == kept
    good = now_frame()
    assert framing.valid_part(good) == (good, [])


def test_an_event_of_a_kind_the_schema_knows_must_fit_it_and_its_key():
    assert "not a valid behavior event: name: 7 is not of type 'string'" in refused(
        EVENT, {"t": 1.0, "kind": "behavior", "name": 7, "state": "started"})
    assert "not a valid behavior event: state" in refused(
        EVENT, {"t": 1.0, "kind": "behavior", "name": "x", "state": {"x": [1]}})
    assert "kind 'conflict' on pepper/events/behavior" in refused(
        EVENT, {"t": 1.0, "kind": "conflict", "state": "owner"})
    unknown = {"t": 1.0, "kind": "status", "anything": [1, "two"]}
    assert Gate().check(Key.parse("pepper/events/status"), pack(unknown)) == unknown


def test_a_robots_joint_names_and_chains_are_plain_unique_chunks():
    info_key = Key.parse("pepper/info")
    good = {"robot": "pepper", "model": "pepper", "rate_hz": 50.0, "behaviors": [], "postures": [],
            "adapter": "x", "schema_version": 1, "owner": {"host": "h", "node": "n"},
            "joints": [{"name": "HeadYaw", "unit": "rad", "min": -2.0, "max": 2.0, "max_velocity": 7.0,
                        "chain": "Head"}]}
    assert Gate().check(info_key, pack(good)) == good
    joint = good["joints"][0]
    assert "chain" in refused(info_key, {**good, "joints": [{**joint, "chain": "**"}]})
    assert "name" in refused(info_key, {**good, "joints": [{**joint, "name": "a/b"}]})
    assert "joint names are not unique" in refused(info_key, {**good, "joints": [joint, joint]})
    assert "max_velocity" in refused(info_key, {**good, "joints": [{**joint, "max_velocity": 1e308}]})


LAYOUT_VALUES = st.one_of(st.floats(-2e6, 2e6), st.just(float("nan")), st.integers(-3, 3), st.booleans(),
                          st.lists(st.one_of(st.floats(-2e6, 2e6), st.integers(-3, 3), st.booleans()), max_size=4),
                          st.lists(st.floats(-1.0, 1.0), min_size=60, max_size=70))


@given(st.lists(st.lists(LAYOUT_VALUES, min_size=4, max_size=4), min_size=2, max_size=8))
@settings(max_examples=300, deadline=None)
def test_one_gate_takes_a_key_s_derived_frames_one_after_another_as_the_schema_says(values):
    """Issue 35: the gate learns where a key's vectors are from its last derived frame (their
    values checked in C); frames whose floats, ints, vectors and their sizes move from one to
    the next are each accepted exactly when the schema accepts them, refused with their reason."""
    gate, key, names = Gate(), Key.parse("pepper/derived"), ["qom/Body", "hand/R", "hand/L", "velocity/A"]
    for seq, v in enumerate(values):
        frame = framing.derived_frame(time.time() - 1.0, seq, names, v)
        try:
            gate.check(key, pack(frame))
            accepted = True
        except BadMessage as exc:
            accepted = False
            assert str(exc).startswith("v["), exc  # (the value's index and what is wrong with it)
        nan = any(x != x for value in v for x in (value if isinstance(value, list) else [value]))
        # (NaN: within the schema's bounds as JSON Schema compares, refused by the gate as no number)
        assert accepted == (schemas.validator("derived_frame").is_valid(frame) and not nan), (
            seq, frame, next(schemas.validator("derived_frame").iter_errors(frame), None))
