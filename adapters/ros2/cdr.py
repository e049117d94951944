"""The three ROS 2 messages sonibus exchanges, in CDR (XCDR1, what rmw_zenoh and the DDS
middlewares put on the wire): ``sensor_msgs/JointState`` read, ``trajectory_msgs/JointTrajectory``
written, ``std_msgs/String`` (``/robot_description``) read. Pure functions over bytes,
with the 4-byte encapsulation header (``00 01`` little endian, ``00 00`` big endian).

Our own rather than rosbags': not for speed (bench/ros2_cdr.py measured it about 1.2×
rosbags' time per JointState here, 50-120 µs on a loaded 2-core machine), but so that a
user's install takes no bag-file stack (rosbags brings SQLite, zstd, lz4, YAML) for three
messages; the tests check both ways against rosbags on many messages. A malformed
payload raises ``CdrError`` saying where; no count is trusted beyond the bytes there.

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

LITTLE, BIG = b"\x00\x01", b"\x00\x00"  # CDR_LE, CDR_BE encapsulation ids (options follow: 2 bytes)
HEADER = 4
MAX_STRING = 4096  # bytes of a joint or frame name; a robot description goes up to the payload itself


class CdrError(ValueError):
    """A payload that is not the message it should be: what was wrong, and at which byte."""


@dataclass(frozen=True)
class Stamp:
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


@dataclass(frozen=True)
class JointState:
    """``sensor_msgs/JointState``: names with positions, velocities and efforts (each may be empty)."""

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


_UINT = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}
_STAMP = {"<": struct.Struct("<iI"), ">": struct.Struct(">iI")}


class _Reader:
    """Reads fields in order, aligned as CDR aligns them (relative to the byte after the header)."""

    def __init__(self, payload: bytes) -> None:
        if len(payload) < HEADER:
            raise CdrError(f"{len(payload)} bytes: shorter than the 4-byte encapsulation header")
        kind = bytes(payload[:2])
        if kind not in (LITTLE, BIG):
            raise CdrError(f"encapsulation {kind.hex()} is not plain CDR (0001 or 0000)")
        self.order = "<" if kind == LITTLE else ">"
        self._uint = _UINT[self.order].unpack_from
        self.data = bytes(payload[HEADER:])
        self.at = 0

    def _short(self, size: int) -> CdrError:
        return CdrError(f"ends at byte {len(self.data) + HEADER}: {size} more bytes needed at byte {self.at + HEADER}")

    def uint(self) -> int:
        self.at += -self.at % 4
        if self.at + 4 > len(self.data):
            raise self._short(4)
        (value,) = self._uint(self.data, self.at)
        self.at += 4
        return int(value)

    def count(self, size: int) -> int:
        n = self.uint()
        if n * size > len(self.data) - self.at:
            raise CdrError(f"a sequence of {n} at byte {self.at + HEADER - 4} is longer than the payload")
        return n

    def string(self, limit: int = MAX_STRING) -> str:
        n = self.count(1)
        if n == 0 or n > limit + 1:
            raise CdrError(f"a string of {n} bytes at byte {self.at + HEADER - 4} (1..{limit + 1} with its NUL)")
        end = self.at + n
        raw = self.data[self.at:end - 1]
        if self.data[end - 1] != 0:
            raise CdrError(f"the string ending at byte {end + HEADER} has no NUL")
        self.at = end
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise CdrError(f"the string ending at byte {end + HEADER} is not UTF-8 ({exc.reason})") from None

    def doubles(self) -> tuple[float, ...]:
        n = self.count(8)
        if not n:
            return ()
        self.at += -self.at % 8
        if self.at + 8 * n > len(self.data):
            raise self._short(8 * n)
        values = struct.unpack_from(f"{self.order}{n}d", self.data, self.at)
        self.at += 8 * n
        return values

    def strings(self) -> tuple[str, ...]:
        return tuple([self.string() for _ in range(self.count(4))])

    def stamp(self) -> Stamp:
        self.at += -self.at % 4
        if self.at + 8 > len(self.data):
            raise self._short(8)
        sec, nanosec = _STAMP[self.order].unpack_from(self.data, self.at)
        self.at += 8
        return Stamp(sec, nanosec)


class _Writer:
    def __init__(self) -> None:
        self.parts: list[bytes] = [LITTLE + b"\x00\x00"]
        self.at = 0

    def _put(self, fmt: str, align: int, *values: object) -> None:
        pad = -self.at % align
        data = b"\x00" * pad + struct.pack("<" + fmt, *values)
        self.parts.append(data)
        self.at += len(data)

    def string(self, text: str) -> None:
        raw = text.encode("utf-8") + b"\x00"
        self._put(f"I{len(raw)}s", 4, len(raw), raw)

    def strings(self, texts: Sequence[str]) -> None:
        self._put("I", 4, len(texts))
        for text in texts:
            self.string(text)

    def doubles(self, values: Sequence[float]) -> None:
        self._put("I", 4, len(values))
        if values:
            self._put(f"{len(values)}d", 8, *values)

    def header(self, stamp: Stamp, frame_id: str) -> None:
        self._put("iI", 4, stamp.sec, stamp.nanosec)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def _done(reader: _Reader, what: str) -> None:
    if len(reader.data) - reader.at >= 4:  # (up to 3 bytes of padding may follow the last field)
        raise CdrError(f"{len(reader.data) - reader.at} bytes left over after the {what}")


def read_joint_state(payload: bytes) -> JointState:
    """A ``sensor_msgs/JointState`` payload; ``CdrError`` if it is not one."""
    r = _Reader(payload)
    stamp, frame_id = r.stamp(), r.string()
    message = JointState(stamp, frame_id, r.strings(), r.doubles(), r.doubles(), r.doubles())
    _done(r, "JointState")
    return message


def joint_state(stamp: Stamp, names: Sequence[str], position: Sequence[float], velocity: Sequence[float] = (),
                effort: Sequence[float] = (), frame_id: str = "") -> bytes:
    """A ``sensor_msgs/JointState`` payload (the simulated arm publishes these)."""
    w = _Writer()
    w.header(stamp, frame_id)
    w.strings(names)
    for values in (position, velocity, effort):
        w.doubles(values)
    return w.bytes()


def joint_trajectory(stamp: Stamp, names: Sequence[str], points: Sequence[Point], frame_id: str = "") -> bytes:
    """A ``trajectory_msgs/JointTrajectory`` payload: velocities as given, accelerations and
    efforts empty (what joint_trajectory_controller reads for a position trajectory)."""
    w = _Writer()
    w.header(stamp, frame_id)
    w.strings(names)
    w._put("I", 4, len(points))
    for point in points:
        w.doubles(point.positions)
        w.doubles(point.velocities)
        w.doubles(())  # accelerations
        w.doubles(())  # effort
        stamp_of = Stamp.of(point.seconds)
        w._put("iI", 4, stamp_of.sec, stamp_of.nanosec)
    return w.bytes()


def read_joint_trajectory(payload: bytes) -> JointTrajectory:
    """A ``trajectory_msgs/JointTrajectory`` payload (the simulated arm follows these)."""
    r = _Reader(payload)
    stamp, frame_id, names = r.stamp(), r.string(), r.strings()
    points = []
    for _ in range(r.count(4 * 4 + 8)):
        positions, velocities, _accelerations, _effort = r.doubles(), r.doubles(), r.doubles(), r.doubles()
        points.append(Point(positions, r.stamp().seconds, velocities))
    _done(r, "JointTrajectory")
    return JointTrajectory(stamp, frame_id, names, tuple(points))


def read_string(payload: bytes, limit: int) -> str:
    """A ``std_msgs/String`` payload (``/robot_description``) of at most ``limit`` bytes."""
    r = _Reader(payload)
    text = r.string(limit)
    _done(r, "String")
    return text


def string(text: str) -> bytes:
    """A ``std_msgs/String`` payload."""
    w = _Writer()
    w.string(text)
    return w.bytes()
