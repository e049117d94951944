"""The velocity filter against analytic trajectories, with and without dropped frames.

A sine ``q = A·sin(2π·f·t)`` has the velocity ``A·ω·cos(ωt)``. The filter is a
first-order low-pass with cut-off ``fc``: its steady output is that velocity
through ``H = 1 / (1 + j·f/fc)`` (gain 0.995, 32 ms lag at f = 0.5 Hz,
fc = 5 Hz). Tolerances (docs/features.md), as fractions of the peak velocity
A·ω, after the first second:

- against H applied to the analytic velocity: 0.5 % (measured ≤ 0.12 % at
  100 Hz, ≤ 0.6 % at 50 Hz with 20 % of the frames dropped, over 20 seeds);
- against the analytic velocity itself: |1 − H| = 9.95 % is the filter's own
  lag, so 10.5 % at 100 Hz.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonibus.adapters.features.filters import VelocityFilter

from .conftest import T0

CUTOFF_HZ = 5.0
AMPLITUDE = 0.5      # rad
FREQUENCY = 0.5      # Hz
TO_FILTERED = {100.0: 0.005, 50.0: 0.01}
TO_ANALYTIC = 0.105


def run(rate_hz: float, drop: float, seed: int = 1, seconds: float = 6.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample times kept, the filter's velocities, and the velocity filtered by the ideal H."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    t = t[(rng.random(len(t)) >= drop) | (t == 0)]
    omega = 2 * np.pi * FREQUENCY
    f = VelocityFilter(1, CUTOFF_HZ)
    out = []
    for ti in t:
        f.update(T0 + ti, np.array([AMPLITUDE * np.sin(omega * ti)]))
        out.append(f.velocity[0])
    h = 1.0 / (1.0 + 1j * FREQUENCY / CUTOFF_HZ)
    ideal = AMPLITUDE * omega * abs(h) * np.cos(omega * t + np.angle(h))
    return t, np.array(out), ideal


@pytest.mark.parametrize("rate_hz", [100.0, 50.0])
@pytest.mark.parametrize("drop", [0.0, 0.2])
def test_velocity_of_a_sine_is_its_low_passed_derivative(rate_hz, drop):
    peak = AMPLITUDE * 2 * np.pi * FREQUENCY
    for seed in range(5):
        t, v, ideal = run(rate_hz, drop, seed)
        settled = t >= 1.0
        assert drop == 0 or len(t) < 0.9 * 6 * rate_hz  # frames really were dropped
        error = np.abs(v - ideal)[settled].max() / peak
        assert error <= TO_FILTERED[rate_hz], f"seed {seed}: {error:.2%} of peak"
        analytic = AMPLITUDE * 2 * np.pi * FREQUENCY * np.cos(2 * np.pi * FREQUENCY * t)
        if rate_hz == 100.0:
            assert np.abs(v - analytic)[settled].max() / peak <= TO_ANALYTIC


def test_dropped_frames_are_longer_steps_not_faster_motion():
    """A ramp of 2 rad/s from rest, frames missing: at every frame the exact low-pass
    response 2·(1 − exp(−t/τ)); a nominal-rate filter would see double the velocity
    across each missing frame."""
    f = VelocityFilter(1, CUTOFF_HZ)
    for ti in [0.00, 0.01, 0.02, 0.05, 0.06, 0.10, 0.20, 0.21]:
        f.update(T0 + ti, np.array([2.0 * ti]))
        assert f.velocity[0] == pytest.approx(2.0 * (1.0 - np.exp(-ti / f.tau)), rel=1e-5)  # t: µs-exact at 1.7e9


def test_nan_is_skipped_and_a_gap_restarts_the_signal():
    f = VelocityFilter(2, CUTOFF_HZ, max_gap_s=0.5)
    assert f.update(T0, np.array([0.0, 0.0])).tolist() == [False, False]
    assert f.update(T0 + 0.01, np.array([0.01, np.nan])).tolist() == [True, False]
    assert f.update(T0 + 0.02, np.array([0.02, 0.02])).tolist() == [True, True]  # over the real 20 ms
    assert f.velocity.tolist() == pytest.approx([1.0 - np.exp(-0.02 / f.tau)] * 2)
    assert f.update(T0 + 1.00, np.array([0.5, 0.5])).tolist() == [False, False]  # 0.98 s later: start over
    assert f.velocity.tolist() == [0.0, 0.0] and not f.known.any()
    assert f.update(T0 + 0.99, np.array([0.5, 0.5])).tolist() == [False, False]  # time went back: start over
    assert f.update(T0 + 1.00, np.array([0.51, 0.5])).tolist() == [True, True]
    assert f.velocity.tolist() == pytest.approx([1.0 - np.exp(-0.01 / f.tau), 0.0])


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="must be more than 0"):
        VelocityFilter(1, cutoff_hz=0.0)


def ramp(f: VelocityFilter, times, glitch: dict[int, float] | None = None) -> list[tuple[bool, float]]:
    """A 1 rad/s ramp through ``f``, with the sample at index ``i`` replaced by ``glitch[i]``:
    (velocity known for that t, velocity) per sample."""
    out = []
    for i, ti in enumerate(times):
        q = (glitch or {}).get(i, ti)
        fresh = f.update(T0 + ti, np.array([q]))
        out.append((bool(fresh[0]), float(f.velocity[0])))
    return out


@pytest.mark.parametrize("glitch", [1e5, -3.0, np.inf, -np.inf], ids=["1e5", "3-rad-jump", "inf", "-inf"])
def test_a_glitch_resets_its_signal_and_the_next_good_samples_are_normal(glitch):
    """At 100 Hz, HeadYaw-like (max 7.34 rad/s): the glitch never reaches the velocity; two
    samples after it the filter gives what a filter started afresh there gives."""
    times = np.arange(30) / 100.0
    f = VelocityFilter(1, CUTOFF_HZ, max_rate=np.array([73.4]))
    got = ramp(f, times, {10: glitch})
    assert all(math.isfinite(v) and abs(v) <= 1.0 for _, v in got), got
    assert f.rejected == (2 if math.isfinite(glitch) else 1)  # a jump there, and back
    assert not got[10][0] and not got[11][0]   # no velocity for the glitch, nor the start after it
    expected = ramp(VelocityFilter(1, CUTOFF_HZ), times[11:])  # a filter started at the next good sample
    assert got[12:] == [(known, pytest.approx(v, abs=1e-9)) for known, v in expected[1:]]
    assert all(known for known, _ in got[12:])


def test_time_going_back_is_refused_and_starts_the_signal_over():
    f = VelocityFilter(1, CUTOFF_HZ)
    for ti in (0.00, 0.01, 0.02):
        f.update(T0 + ti, np.array([ti]))
    assert f.update(T0 - 5.0, np.array([0.03])).tolist() == [False]
    assert f.rejected == 1 and f.refused.tolist() == [True] and f.velocity.tolist() == [0.0]
    assert f.update(T0 - 4.99, np.array([0.04])).tolist() == [True]   # on from the refused sample
    assert f.velocity[0] == pytest.approx(1.0 - np.exp(-0.01 / f.tau))
    assert f.refused.tolist() == [False]


def test_without_a_max_rate_a_velocity_beyond_float_is_never_kept():
    f = VelocityFilter(2, CUTOFF_HZ)
    f.update(T0, np.array([0.0, 0.0]))
    f.update(T0 + 1e-6, np.array([1.7e308, 0.0]))   # a rate of 1.7e314: not a float
    assert np.isfinite(f.velocity).all() and f.velocity[0] == 0.0
    assert f.refused.tolist() == [True, False]
    f.update(T0 + 0.01, np.array([0.0, 0.01]))      # nothing left to start over from but this sample
    f.update(T0 + 0.02, np.array([0.01, 0.02]))
    assert f.velocity.tolist() == pytest.approx([1.0 - np.exp(-0.01 / f.tau), f.velocity[1]])


def test_a_max_rate_is_one_positive_number_per_signal():
    with pytest.raises(ValueError, match="max_rate must be 2 values more than 0"):
        VelocityFilter(2, CUTOFF_HZ, max_rate=np.array([1.0]))
    with pytest.raises(ValueError, match="max_rate"):
        VelocityFilter(1, CUTOFF_HZ, max_rate=np.array([0.0]))


def test_a_joint_that_stops_comes_to_rest_at_zero_not_at_tiny_numbers():
    """Issue 19, item 6: the features CSV held velocities like 1.9e-228 long after a stop."""
    f = VelocityFilter(2, cutoff_hz=5.0)
    for k in range(100):  # moves at 1 rad/s, then holds still for 9 s
        f.update(k * 0.01, np.array([min(k, 10) * 0.01, 0.0]))
    held_a_second = f.velocity.copy()
    for k in range(100, 1000):
        f.update(k * 0.01, np.array([0.1, 0.0]))
    assert held_a_second[0] == 0.0 and f.velocity.tolist() == [0.0, 0.0]
    g = VelocityFilter(1, cutoff_hz=5.0)
    for k in range(30):
        g.update(k * 0.01, np.array([k * 0.01]))
    assert 0.9 < g.velocity[0] < 1.1  # a real motion is untouched
