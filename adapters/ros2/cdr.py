"""The three ROS 2 messages sonibus exchanges, in CDR (XCDR1, what rmw_zenoh and the DDS
middlewares put on the wire): ``sensor_msgs/JointState`` read, ``trajectory_msgs/JointTrajectory``
written, ``std_msgs/String`` (``/robot_description``) read. Pure functions over bytes,
with the 4-byte encapsulation header (``00 01`` little endian, ``00 00`` big endian: both read).

Our own rather than rosbags', for speed and weight: a JointState is read straight off the
payload with precompiled ``struct.Struct``s (one call per float64 run, offsets rather than
copies, a robot's joint names not decoded again), in a quarter of the instructions of
rosbags' generic decoder at 17 joints (bench/ros2_cdr.py, docs/ros2.md "Cost"), and a
user's install takes no bag-file stack (rosbags brings SQLite, zstd, lz4, YAML) for three
messages. The tests check both ways against rosbags on many messages, both byte orders. A
malformed payload raises ``CdrError`` saying where; no count is trusted beyond the bytes there.

>>> payload = joint_state(Stamp(3, 500_000_000), ["j1", "j2"], [0.5, -1.0])
>>> state = read_joint_state(payload)
>>> state.names, state.position, state.stamp.seconds
(('j1', 'j2'), (0.5, -1.0), 3.5)
>>> read_joint_trajectory(joint_trajectory(Stamp(0, 0), ["j1"], [Point([0.1], 1.5)])).points
(Point(positions=(0.1,), seconds=1.5, velocities=()),)
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

LITTLE, BIG = b"\x00\x01", b"\x00\x00"  # CDR_LE, CDR_BE encapsulation ids (options follow: 2 bytes)
HEADER = 4
MAX_STRING = 4096  # bytes of a joint or frame name; a robot description goes up to the payload itself
NAME_SEQUENCES, MAX_REMEMBERED = 8, 1 << 16  # name sequences remembered (several robots), their bytes at most
MAX_STRUCTS = 256  # float64 runs of this many lengths kept compiled, per byte order (lengths come from the network)


class CdrError(ValueError):
    """A payload that is not the message it should be: what was wrong, and at which byte."""


class Stamp(NamedTuple):
    """``builtin_interfaces/Time``: seconds and nanoseconds since the epoch."""

    sec: int
    nanosec: int

    @property
    def seconds(self) -> float:
        return self.sec + self.nanosec * 1e-9

    @staticmethod
    def of(t: float) -> Stamp:
        sec = math.floor(t)
        return Stamp(sec, min(999_999_999, round((t - sec) * 1e9)))


class JointState(NamedTuple):
    """``sensor_msgs/JointState``: names with positions, velocities and efforts (each may be empty).
    A named tuple, as ``Stamp``: one is made per message, a fifth of a frozen dataclass's cost."""

    stamp: Stamp
    frame_id: str
    names: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]


@dataclass(frozen=True)
class Point:
    """A ``trajectory_msgs/JointTrajectoryPoint``: positions reached ``seconds`` after the start."""

    positions: tuple[float, ...] | list[float]
    seconds: float
    velocities: tuple[float, ...] | list[float] = ()


@dataclass(frozen=True)
class JointTrajectory:
    stamp: Stamp
    frame_id: str
    names: tuple[str, ...]
    points: tuple[Point, ...]


# -- reading: offsets into the payload itself (no copy); CDR aligns relative to byte 4 ------

class _Order:
    """One byte order's precompiled Structs."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        uint, stamp = struct.Struct(prefix + "I"), struct.Struct(prefix + "iI")
        self.uint, self.pack_uint = uint.unpack_from, uint.pack
        self.stamp, self.pack_stamp = stamp.unpack_from, stamp.pack
        self._floats: dict[int, struct.Struct] = {}

    def floats(self, n: int) -> struct.Struct:
        """The Struct of ``n`` float64."""
        packing = self._floats.get(n)
        if packing is None:
            packing = struct.Struct(f"{self.prefix}{n}d")
            if len(self._floats) < MAX_STRUCTS:
                self._floats[n] = packing
        return packing


_tuple = tuple.__new__  # a named tuple made from its fields' tuple without its Python-level __new__
_LE = _Order("<")
_ORDERS = {LITTLE: _LE, BIG: _Order(">")}
_NAMES: tuple[tuple[_Order, bytes, tuple[str, ...]], ...] = ()  # (byte order, bytes, names) read lately, newest first


def _begin(payload: Any) -> tuple[bytes, _Order]:
    if type(payload) is not bytes:
        payload = bytes(payload)
    if len(payload) < HEADER:
        raise CdrError(f"{len(payload)} bytes: shorter than the 4-byte encapsulation header")
    order = _ORDERS.get(payload[:2])
    if order is None:
        raise CdrError(f"encapsulation {payload[:2].hex()} is not plain CDR (0001 or 0000)")
    return payload, order


def _short(p: int, size: int, end: int) -> CdrError:
    return CdrError(f"ends at byte {end}: {size} more bytes needed at byte {p}")


def _uint(buf: bytes, p: int, end: int, order: _Order) -> tuple[int, int]:
    p += -p & 3
    if p + 4 > end:
        raise _short(p, 4, end)
    return order.uint(buf, p)[0], p + 4


def _count(buf: bytes, p: int, end: int, order: _Order, size: int) -> tuple[int, int]:
    """A sequence's length, refused if ``size`` bytes each would not fit in what is left."""
    n, p = _uint(buf, p, end, order)
    if n * size > end - p:
        raise CdrError(f"a sequence of {n} at byte {p - 4} is longer than the payload")
    return n, p


def _stamp(buf: bytes, p: int, end: int, order: _Order) -> tuple[Stamp, int]:
    p += -p & 3
    if p + 8 > end:
        raise _short(p, 8, end)
    return _tuple(Stamp, order.stamp(buf, p)), p + 8


def _bad_string(buf: bytes, p: int, n: int, end: int, limit: int) -> CdrError:
    """Why the string of ``n`` bytes (its NUL included) that starts at byte ``p`` is refused."""
    if n > end - p:
        return CdrError(f"a string of {n} bytes at byte {p - 4} is longer than the payload")
    if n == 0 or n > limit + 1:
        return CdrError(f"a string of {n} bytes at byte {p - 4} (1..{limit + 1} with its NUL)")
    return CdrError(f"the string ending at byte {p + n} has no NUL")


def _not_utf8(q: int, exc: UnicodeDecodeError) -> CdrError:
    return CdrError(f"the string ending at byte {q} is not UTF-8 ({exc.reason})")


def _string(buf: bytes, p: int, end: int, order: _Order, limit: int = MAX_STRING) -> tuple[str, int]:
    n, p = _uint(buf, p, end, order)
    q = p + n
    if n == 0 or n > limit + 1 or q > end or buf[q - 1]:
        raise _bad_string(buf, p, n, end, limit)
    try:
        return buf[p:q - 1].decode(), q
    except UnicodeDecodeError as exc:
        raise _not_utf8(q, exc) from None


def _strings(buf: bytes, p: int, end: int, order: _Order) -> tuple[tuple[str, ...], int]:
    """A sequence of strings: ``_string``'s checks, in one loop. A robot sends the same joint
    names in every JointState: bytes equal to a sequence read before are that sequence again
    (the same bytes at a 4-aligned start read the same), so they are compared, not reread."""
    global _NAMES
    p += -p & 3
    for known_order, region, known in _NAMES:
        if known_order is order and buf.startswith(region, p):
            return known, p + len(region)
    start = p
    count, q = _count(buf, p, end, order, 4)
    uint, names = order.uint, []
    try:
        for _ in range(count):
            p = q + (-q & 3)
            if p + 4 > end:
                raise _short(p, 4, end)
            (n,) = uint(buf, p)
            p += 4
            q = p + n
            if n == 0 or n > MAX_STRING + 1 or q > end or buf[q - 1]:
                raise _bad_string(buf, p, n, end, MAX_STRING)
            names.append(buf[p:q - 1].decode())
    except UnicodeDecodeError as exc:
        raise _not_utf8(q, exc) from None
    result = tuple(names)
    if q - start <= MAX_REMEMBERED:  # (a new tuple swapped in: other threads see the old one or this, whole)
        _NAMES = ((order, buf[start:q], result), *_NAMES[:NAME_SEQUENCES - 1])
    return result, q


def _doubles(buf: bytes, p: int, end: int, order: _Order) -> tuple[tuple[float, ...], int]:
    """A float64 sequence: one unpack for the run, 8-aligned (relative to byte 4) when not empty."""
    n, p = _uint(buf, p, end, order)
    if not n:
        return (), p
    p += (4 - p) & 7
    q = p + 8 * n
    if q > end:
        raise CdrError(f"a sequence of {n} float64 at byte {p} is longer than the payload")
    return order.floats(n).unpack_from(buf, p), q


def _done(p: int, end: int, what: str) -> None:
    if end - p >= 4:  # (up to 3 bytes of padding may follow the last field)
        raise CdrError(f"{end - p} bytes left over after the {what}")


def _named(payload: bytes) -> tuple[bytes, _Order, tuple[Stamp, str, tuple[str, ...]], int]:
    """What both joint messages start with, a Header and the joint names: the payload, its
    byte order, (stamp, frame_id, names), and the byte after them."""
    buf, order = _begin(payload)
    end = len(buf)
    stamp, p = _stamp(buf, HEADER, end, order)
    frame_id, p = _string(buf, p, end, order)
    names, p = _strings(buf, p, end, order)
    return buf, order, (stamp, frame_id, names), p


def read_joint_state(payload: bytes) -> JointState:
    """A ``sensor_msgs/JointState`` payload; ``CdrError`` if it is not one."""
    buf, order, head, p = _named(payload)
    end = len(buf)
    position, p = _doubles(buf, p, end, order)
    velocity, p = _doubles(buf, p, end, order)
    effort, p = _doubles(buf, p, end, order)
    _done(p, end, "JointState")
    return _tuple(JointState, (*head, position, velocity, effort))


def read_joint_trajectory(payload: bytes) -> JointTrajectory:
    """A ``trajectory_msgs/JointTrajectory`` payload (the simulated arm follows these)."""
    buf, order, head, p = _named(payload)
    end = len(buf)
    count, p = _count(buf, p, end, order, 4 * 4 + 8)
    points = []
    for _ in range(count):
        positions, p = _doubles(buf, p, end, order)
        velocities, p = _doubles(buf, p, end, order)
        for _unread in range(2):  # accelerations, effort
            _, p = _doubles(buf, p, end, order)
        duration, p = _stamp(buf, p, end, order)
        points.append(Point(positions, duration.seconds, velocities))
    _done(p, end, "JointTrajectory")
    return JointTrajectory(*head, tuple(points))


def read_string(payload: bytes, limit: int) -> str:
    """A ``std_msgs/String`` payload (``/robot_description``) of at most ``limit`` bytes."""
    buf, order = _begin(payload)
    text, p = _string(buf, HEADER, len(buf), order, limit)
    _done(p, len(buf), "String")
    return text


# -- writing: little endian, as rosbags and the DDS middlewares write ---------------------

_ZEROS = tuple(bytes(n) for n in range(8))  # padding, by its length


class _Writer:
    """Fields appended in order, aligned as CDR aligns them (relative to byte 4), little endian."""

    def __init__(self) -> None:
        self.buf = bytearray(LITTLE + b"\x00\x00")

    def uint(self, value: int) -> None:
        self.buf += _ZEROS[-len(self.buf) & 3]
        self.buf += _LE.pack_uint(value)

    def stamp(self, stamp: Stamp) -> None:
        self.buf += _ZEROS[-len(self.buf) & 3]
        self.buf += _LE.pack_stamp(*stamp)

    def string(self, text: str) -> None:
        raw = text.encode()
        self.uint(len(raw) + 1)
        self.buf += raw
        self.buf.append(0)

    def strings(self, texts: Sequence[str]) -> None:
        self.uint(len(texts))
        buf, pack = self.buf, _LE.pack_uint
        for text in texts:  # (string() inlined: a trajectory names every joint)
            raw = text.encode()
            buf += _ZEROS[-len(buf) & 3]
            buf += pack(len(raw) + 1)
            buf += raw
            buf.append(0)

    def doubles(self, values: Sequence[float]) -> None:
        self.uint(len(values))
        if values:
            self.buf += _ZEROS[(4 - len(self.buf)) & 7]
            self.buf += _LE.floats(len(values)).pack(*values)

    def bytes(self) -> bytes:
        return bytes(self.buf)


def joint_state(stamp: Stamp, names: Sequence[str], position: Sequence[float], velocity: Sequence[float] = (),
                effort: Sequence[float] = (), frame_id: str = "") -> bytes:
    """A ``sensor_msgs/JointState`` payload (the simulated arm publishes these)."""
    w = _Writer()
    w.stamp(stamp)
    w.string(frame_id)
    w.strings(names)
    for values in (position, velocity, effort):
        w.doubles(values)
    return w.bytes()


def joint_trajectory(stamp: Stamp, names: Sequence[str], points: Sequence[Point], frame_id: str = "") -> bytes:
    """A ``trajectory_msgs/JointTrajectory`` payload: velocities as given, accelerations and
    efforts empty (what joint_trajectory_controller reads for a position trajectory)."""
    w = _Writer()
    w.stamp(stamp)
    w.string(frame_id)
    w.strings(names)
    w.uint(len(points))
    for point in points:
        w.doubles(point.positions)
        w.doubles(point.velocities)
        w.doubles(())  # accelerations
        w.doubles(())  # effort
        w.stamp(Stamp.of(point.seconds))  # time_from_start
    return w.bytes()


def string(text: str) -> bytes:
    """A ``std_msgs/String`` payload."""
    w = _Writer()
    w.string(text)
    return w.bytes()
