"""Our CDR against rosbags' on many messages, both ways; malformed payloads raise CdrError only."""

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


def _rosbags_state(stamp, frame_id, joint_names, position, velocity, effort) -> bytes:
    header = TYPES.types["std_msgs/msg/Header"](
        stamp=TYPES.types["builtin_interfaces/msg/Time"](sec=stamp.sec, nanosec=stamp.nanosec), frame_id=frame_id)
    return bytes(TYPES.serialize_cdr(TYPES.types[JOINT_STATE](
        header=header, name=joint_names, position=np.array(position, dtype=np.float64),
        velocity=np.array(velocity, dtype=np.float64), effort=np.array(effort, dtype=np.float64)), JOINT_STATE))


@settings(max_examples=120, deadline=None)
@given(stamps, st.text(max_size=10).filter(lambda s: "\x00" not in s), names, st.data())
def test_joint_states_rosbags_encodes_we_decode_and_back(stamp, frame_id, joint_names, data):
    n = len(joint_names)
    position = data.draw(st.lists(floats, min_size=n, max_size=n))
    velocity = data.draw(st.sampled_from([[], *([position] if n else [])]))
    effort = data.draw(st.lists(floats, min_size=n, max_size=n) | st.just([]))
    theirs = _rosbags_state(stamp, frame_id, joint_names, position, velocity, effort)
    state = cdr.read_joint_state(theirs)
    assert (state.stamp, state.frame_id, list(state.names)) == (stamp, frame_id, joint_names)
    assert (list(state.position), list(state.velocity), list(state.effort)) == (position, velocity, effort)
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


def test_every_truncation_of_a_joint_state_is_refused():
    whole = _rosbags_state(cdr.Stamp(1, 2), "base", ["a", "b"], [1.0, 2.0], [0.1, 0.2], [])
    for size in range(len(whole) - 3):  # (up to 3 bytes of trailing padding are not a field)
        try:
            cdr.read_joint_state(whole[:size])
        except cdr.CdrError as exc:
            assert "\n" not in str(exc)
        else:
            raise AssertionError(f"{size} of {len(whole)} bytes decoded")


def test_a_count_beyond_the_payload_is_refused_before_it_is_believed():
    whole = bytearray(_rosbags_state(cdr.Stamp(1, 2), "", ["a"], [1.0], [], []))
    whole[20:24] = (2**31).to_bytes(4, "little")  # the names' count: two billion
    try:
        cdr.read_joint_state(bytes(whole))
    except cdr.CdrError as exc:
        assert "longer than the payload" in str(exc)
    else:
        raise AssertionError("decoded")
