"""Checking that a stream is paced by ``seq`` without timing the test machine."""

from __future__ import annotations

from collections.abc import Sequence


def drift_frames(stamps: Sequence[tuple[int, float]], rate_hz: float) -> float:
    """How far ``seq`` drifts from ``t`` over ``stamps`` ((seq, t) in order), in frames: the
    least late frame of the second half against the least late of the first.

    A busy machine stamps frames late, never early, so the least late frame of each half is
    near its deadline however loaded the machine is; a loop not paced by seq (one that
    sleeps a period after its work, or runs at another rate) drifts by frames a second.

    >>> round(drift_frames([(0, 10.0), (1, 10.03), (2, 10.02), (3, 10.031)], 100.0), 1)  # 2 on time
    0.0
    >>> round(drift_frames([(0, 10.0), (1, 10.013), (2, 10.026), (3, 10.039)], 100.0), 1)  # +3 ms a frame
    0.6
    """
    late = [t - seq / rate_hz for seq, t in stamps]
    half = len(late) // 2
    return (min(late[half:]) - min(late[:half])) * rate_hz
