"""Values ↔ MIDI numbers, and MIDI messages as bytes (no ports, no timing).

>>> scale(0.0, -2.0, 2.0, 127)
64
>>> cc_messages(1, 7, 8192, 14)      # MSB on CC 7, LSB on CC 39
[[176, 7, 64], [176, 39, 0]]
>>> pitch_bend(2, 16383)
[[225, 127, 127]]
>>> unscale(127, 127, -1.0, 1.0)
1.0
>>> behavior_note("animations/Stand/Gestures/Hey_1"), behavior_note("animations/Stand/Gestures/Yes_1")
(94, 118)
"""

from __future__ import annotations

import math
import zlib

FIRST_CC = 20          # default controllers: joint i of the robot's table on CC 20 + i
BEHAVIOR_NOTES = (60, 127)  # the notes behaviors are hashed onto, by default
SPEECH_NOTE = 48
ALL_NOTES_OFF = 123
MAX7, MAX14 = 127, 16383


def scale(value: float, low: float, high: float, top: int) -> int:
    """``value`` in ``[low, high]`` → ``0..top`` (clamped, rounded)."""
    if not high > low:
        return 0
    fraction = min(1.0, max(0.0, (value - low) / (high - low)))
    return round(fraction * top)


def span(low: float, high: float) -> float:
    """What ``scale`` divides by, for a caller that inlines it on a hot path:
    ``round(min(1.0, max(0.0, (value - low) / span(low, high))) * top)`` is
    ``scale(value, low, high, top)`` for every finite ``value`` (an empty range's
    span is infinite: every value gives 0, as ``scale`` does).

    >>> values = [-3.0, -2.0, -0.7, 0.0, 0.123456789, 1.999, 2.0, 7.5]
    >>> all(round(min(1.0, max(0.0, (v - lo) / span(lo, hi))) * 127) == scale(v, lo, hi, 127)
    ...     for v in values for lo, hi in ((-2.0, 2.0), (0.5, 0.5), (1.0, -1.0), (-0.3, 1.7)))
    True
    """
    return high - low if high > low else math.inf


def unscale(number: int, top: int, low: float, high: float) -> float:
    """``0..top`` → ``[low, high]``."""
    return low + (high - low) * min(top, max(0, number)) / top


def cc_messages(channel: int, cc: int, number: int, resolution: int) -> list[list[int]]:
    """Control change(s) for ``number`` on ``channel`` (1..16): one at 7 bits, MSB then LSB at 14."""
    status = 0xB0 | (channel - 1)
    if resolution == 14:
        return [[status, cc, number >> 7], [status, cc + 32, number & 0x7F]]
    return [[status, cc, number]]


def pitch_bend(channel: int, number: int) -> list[list[int]]:
    """A 14-bit pitch bend (8192: centre)."""
    return [[0xE0 | (channel - 1), number & 0x7F, number >> 7]]


def behavior_note(name: str, low: int = BEHAVIOR_NOTES[0], high: int = BEHAVIOR_NOTES[1]) -> int:
    """The note of behavior ``name`` in ``low..high``: from a hash of its name (CRC-32,
    the same on every machine and in every run), so installing another behavior on
    the robot moves no note of a live set. Two names may share a note: the sink
    says so, and ``behavior_notes`` gives one of them another."""
    return low + zlib.crc32(name.encode("utf-8")) % (high - low + 1)


def note(channel: int, number: int, on: bool, velocity: int = 100) -> list[int]:
    return [(0x90 if on else 0x80) | (channel - 1), number, velocity if on else 0]


def all_notes_off(channel: int) -> list[int]:
    return [0xB0 | (channel - 1), ALL_NOTES_OFF, 0]
