"""The simulator's frame stamps: ``t`` and the motion's time from one reading of the clock."""

from __future__ import annotations

import random

from sonibus.adapters.sim.adapter import Stamps


def readings(n: int, seed: int = 3, step_at: int | None = None) -> list[tuple[float, float]]:
    """(wall, monotonic) read at 100 Hz, the wall clock read up to 0.3 ms away from the monotonic
    one (a thread preempted between the two reads), and, from ``step_at``, set 10 s ahead."""
    rng = random.Random(seed)
    out, mono = [], 50.0
    for i in range(n):
        mono += 0.01 + rng.uniform(-0.002, 0.002)
        wall = 1.7e9 + mono + rng.uniform(-0.0003, 0.0003) + (10.0 if step_at is not None and i >= step_at else 0)
        out.append((wall, mono))
    return out


def test_t_advances_as_the_motion_does_whatever_the_reads_jitter():
    clock = iter(readings(2001))
    stamps = Stamps(lambda: next(clock))
    last_t = None
    for _ in range(2000):
        t, dt = stamps.next()
        if last_t is not None:  # (a joint moved at its limit over dt shows at most 0.1 % faster by t; 1 µs:
            # a double near 1.7e9 s is exact to 0.24 µs)
            assert abs((t - last_t) - dt) <= Stamps.SLEW * dt + 1e-6, (t - last_t, dt)
        last_t = t


def test_t_stays_near_the_wall_clock_and_follows_it_when_it_is_set():
    data = readings(2001, step_at=1000)
    clock = iter(data)
    stamps = Stamps(lambda: next(clock))
    for i in range(2000):
        t, _ = stamps.next()
        assert abs(t - data[i + 1][0]) < 0.001, f"frame {i}: t {t} vs the wall clock {data[i + 1][0]}"
