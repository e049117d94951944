"""Our CDR against rosbags' on many messages, both ways and both byte orders; malformed
payloads raise CdrError only, whether the joint names were read before or not."""

from __future__ import annotations

import contextlib

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.adapters.ros2 import cdr

from .conftest import JOINT_STATE, TRAJECTORY, TYPES

names = st.lists(st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12), max_size=8)
floats = st.floats(allow_nan=False, width=64)
stamps = st.builds(cdr.Stamp, st.integers(-2**31, 2**31 - 1), st.integers(0, 999_999_999))


def _rosbags_state(stamp, frame_id, joint_names, position, velocity, effort, little_endian=True) -> bytes:
    header = TYPES.types["std_msgs/msg/Header"](
        stamp=TYPES.types["builtin_interfaces/msg/Time"](sec=stamp.sec, nanosec=stamp.nanosec), frame_id=frame_id)
    return bytes(TYPES.serialize_cdr(TYPES.types[JOINT_STATE](
        header=header, name=joint_names, position=np.array(position, dtype=np.float64),
        velocity=np.array(velocity, dtype=np.float64), effort=np.array(effort, dtype=np.float64)), JOINT_STATE,
        little_endian=little_endian))


def _forget_names():
    cdr._NAMES = ()  # the name sequences the decoder remembers: the next decode reads every byte


@settings(max_examples=120, deadline=None)
@given(stamps, st.text(max_size=10).filter(lambda s: "\x00" not in s), names, st.data())
def test_joint_states_rosbags_encodes_we_decode_and_back(stamp, frame_id, joint_names, data):
    n = len(joint_names)
    position = data.draw(st.lists(floats, min_size=n, max_size=n))
    velocity = data.draw(st.sampled_from([[], *([position] if n else [])]))
    effort = data.draw(st.lists(floats, min_size=n, max_size=n) | st.just([]))
    theirs = _rosbags_state(stamp, frame_id, joint_names, position, velocity, effort)
    _forget_names()
    state = cdr.read_joint_state(theirs)
    assert (state.stamp, state.frame_id, list(state.names)) == (stamp, frame_id, joint_names)
    assert (list(state.position), list(state.velocity), list(state.effort)) == (position, velocity, effort)
    assert cdr.read_joint_state(theirs) == state  # its names remembered this time
    big = _rosbags_state(stamp, frame_id, joint_names, position, velocity, effort, little_endian=False)
    assert big[:2] == cdr.BIG and cdr.read_joint_state(big) == state
    ours = cdr.joint_state(stamp, joint_names, position, velocity, effort, frame_id)
    assert ours == theirs  # byte for byte
    decoded = TYPES.deserialize_cdr(ours, JOINT_STATE)
    assert decoded.name == joint_names and decoded.position.tolist() == position


@settings(max_examples=80, deadline=None)
@given(names, st.data())
def test_our_trajectories_decode_in_rosbags_and_match_its_bytes(joint_names, data):
    n = len(joint_names)
    points = data.draw(st.lists(st.builds(cdr.Point, st.lists(floats, min_size=n, max_size=n),
                                          st.floats(0, 1e6), st.lists(floats, min_size=n, max_size=n) | st.just([])),
                                max_size=4))
    ours = cdr.joint_trajectory(cdr.Stamp(0, 0), joint_names, points)
    decoded = TYPES.deserialize_cdr(ours, TRAJECTORY)
    assert decoded.joint_names == joint_names and len(decoded.points) == len(points)
    for point, theirs in zip(points, decoded.points, strict=True):
        assert theirs.positions.tolist() == list(point.positions)
        assert theirs.velocities.tolist() == list(point.velocities)
        seconds = theirs.time_from_start.sec + theirs.time_from_start.nanosec * 1e-9
        assert abs(seconds - point.seconds) <= 1e-9 * max(1.0, point.seconds)
    assert bytes(TYPES.serialize_cdr(decoded, TRAJECTORY)) == ours
    assert cdr.read_joint_trajectory(ours).names == tuple(joint_names)


def test_a_robot_description_string_both_ways():
    text = "<robot name='ü'>" + "x" * 5000 + "</robot>"
    theirs = bytes(TYPES.serialize_cdr(TYPES.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))
    assert cdr.read_string(theirs, 1 << 20) == text and cdr.string(text) == theirs


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_any_bytes_decode_or_raise_cdr_error(payload):
    for read in (cdr.read_joint_state, cdr.read_joint_trajectory):
        with contextlib.suppress(cdr.CdrError):  # (anything else fails the test)
            read(b"\x00\x01\x00\x00" + payload)


def _outcome(payload: bytes) -> str:
    try:
        return repr(cdr.read_joint_state(payload))  # (a repr: NaN equals NaN there)
    except cdr.CdrError as exc:  # (anything else fails the test)
        assert "\n" not in str(exc)
        return f"CdrError: {exc}"


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 10**6), st.binary(min_size=1, max_size=4), st.booleans())
def test_a_joint_state_with_bytes_overwritten_reads_the_same_whether_its_names_were_read_before(where, new, little):
    whole = _rosbags_state(cdr.Stamp(1, 2), "odd", ["a", "bcd", "ef"], [1.0, 2.0, 3.0], [], [4.0, 5.0, 6.0], little)
    at = 4 + where % (len(whole) - 4)
    changed = whole[:at] + new + whole[at + len(new):]
    _forget_names()
    cold = _outcome(changed)
    _forget_names()
    cdr.read_joint_state(whole)
    assert _outcome(changed) == cold
    names_end = whole.index(b"ef\x00") + 3
    if at >= names_end and not cold.startswith("CdrError"):
        assert "names=('a', 'bcd', 'ef')" in cold


def test_every_truncation_of_a_joint_state_is_refused():
    for little in (True, False):
        whole = _rosbags_state(cdr.Stamp(1, 2), "base", ["a", "b"], [1.0, 2.0], [0.1, 0.2], [], little)
        for remembered in (False, True):  # (its names read before: only the bytes after them are read)
            for size in range(len(whole) - 3):  # (up to 3 bytes of trailing padding are not a field)
                _forget_names()
                if remembered:
                    cdr.read_joint_state(whole)
                try:
                    cdr.read_joint_state(whole[:size])
                except cdr.CdrError as exc:
                    assert "\n" not in str(exc)
                else:
                    raise AssertionError(f"{size} of {len(whole)} bytes decoded")


def test_names_read_in_one_byte_order_are_not_taken_for_the_other():
    little, big = (_rosbags_state(cdr.Stamp(1, 2), "", ["a"], [], [], [], order) for order in (True, False))
    assert cdr.read_joint_state(little).names == ("a",)
    crossed = big[:20] + little[20:30] + big[30:]  # the little-endian names (bytes 20-29) in a big-endian message
    try:
        cdr.read_joint_state(crossed)  # its count, 01 00 00 00, is 16 million in big endian
    except cdr.CdrError as exc:
        assert "a sequence of 16777216 at byte 20 is longer than the payload" in str(exc)
    else:
        raise AssertionError("decoded")


def test_other_encapsulations_are_refused_in_one_line():
    whole = _rosbags_state(cdr.Stamp(1, 2), "", ["a"], [1.0], [], [])
    for kind in (b"\x00\x03", b"\x00\x07", b"\x00\x11"):  # PL_CDR_LE, CDR2_LE (XCDR2), PL_CDR2_LE
        try:
            cdr.read_joint_state(kind + whole[2:])
        except cdr.CdrError as exc:
            assert str(exc) == f"encapsulation {kind.hex()} is not plain CDR (0001 or 0000)"
        else:
            raise AssertionError(f"{kind.hex()} decoded")


def test_a_count_beyond_the_payload_is_refused_before_it_is_believed():
    whole = bytearray(_rosbags_state(cdr.Stamp(1, 2), "", ["a"], [1.0], [], []))
    whole[20:24] = (2**31).to_bytes(4, "little")  # the names' count: two billion
    try:
        cdr.read_joint_state(bytes(whole))
    except cdr.CdrError as exc:
        assert "longer than the payload" in str(exc)
    else:
        raise AssertionError("decoded")


def test_every_padding_before_the_float64_runs_both_orders():
    for frame_length in range(8):  # the names then start 0-3 bytes past a 4-byte boundary...
        for name_length in range(1, 9):  # ...and the float64 run 0-7 bytes past an 8-byte one
            for little in (True, False):
                args = (cdr.Stamp(5, 6), "f" * frame_length, ["n" * name_length, "m"], [0.5, -0.5], [], [1.0, 2.0])
                theirs = _rosbags_state(*args, little)
                state = cdr.read_joint_state(theirs)
                assert (state.frame_id, state.names, state.position, state.effort) == (args[1], tuple(args[2]),
                                                                                       (0.5, -0.5), (1.0, 2.0))
                if little:
                    assert cdr.joint_state(args[0], args[2], args[3], args[4], args[5], args[1]) == theirs


def test_what_the_decoder_keeps_for_lengths_and_names_from_the_network_is_bounded():
    for n in range(1, cdr.MAX_STRUCTS + 40):  # float64 runs of as many lengths
        cdr.read_joint_state(cdr.joint_state(cdr.Stamp(0, 0), [], [], effort=[0.0] * n))
    assert all(len(order._floats) <= cdr.MAX_STRUCTS for order in cdr._ORDERS.values())
    for n in range(3 * cdr.NAME_SEQUENCES):  # as many robots' names
        cdr.read_joint_state(cdr.joint_state(cdr.Stamp(0, 0), [f"robot{n}_joint"], [0.0]))
    assert len(cdr._NAMES) == cdr.NAME_SEQUENCES
    huge = [f"j{i:0{cdr.MAX_STRING - 8}}" for i in range(20)]  # 80 KiB of names: read, not kept
    assert cdr.read_joint_state(cdr.joint_state(cdr.Stamp(0, 0), huge, [0.0] * 20)).names == tuple(huge)
    assert all(len(region) <= cdr.MAX_REMEMBERED for _, region, _ in cdr._NAMES)
