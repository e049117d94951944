"""Velocities of sampled signals, smoothed, from the samples' own times.

Per signal, the mean velocity over each step, ``r_k = (q_k − q_(k-1)) / Δt_k``,
goes through a first-order low-pass with cut-off ``fc`` (Hz), ``τ = 1/(2π·fc)``,
solved exactly for a velocity that changes linearly across the step (the
slope ``s_k`` taken from the previous step):

    v_k = e_k · v_(k-1) + (1 − e_k) · (r_k + s_k · δ_k)
    e_k = exp(−Δt_k / τ)
    s_k = (r_k − r_(k-1)) / ((Δt_k + Δt_(k-1)) / 2)
    δ_k = Δt_k / 2 − τ + Δt_k · e_k / (1 − e_k)     (where the filter's weight
                                                     sits, after the step's middle)

Every step uses its real ``Δt``, so a dropped frame is a longer step, not a
wrong velocity. A velocity below ``STILL`` (1e-9 units/s) is 0: a joint that
stopped comes to rest, not through ever smaller numbers to 1e-300. A signal's
first sample (and the first after a gap longer than ``max_gap_s``) starts it
over from rest (``v = 0``, no slope), so a start makes no burst from noise. A
NaN sample is no sample: that signal keeps its state.

Poison never stays in the state. A sample the filter refuses (``rejected``,
counted) resets its signal instead: one whose time went backwards, or that
jumped faster than ``max_rate`` allows (a glitch far beyond what the joint can
do), starts the signal over from itself; an infinite one starts it over from
the next sample; a velocity that would not be finite is never kept. So after
one bad sample the next good ones give normal velocities again.

>>> f = VelocityFilter(1, cutoff_hz=5.0)
>>> f.update(0.00, np.array([0.0])).tolist(), f.update(0.01, np.array([0.01])).tolist()
([False], [True])
>>> f.velocity.round(3).tolist()          # 1 rad/s from rest: 1 − exp(−0.01 / τ)
[0.27]
>>> g = VelocityFilter(1, cutoff_hz=5.0, max_rate=np.array([70.0]))
>>> [g.update(t, np.array([q])).tolist() for t, q in [(0.00, 0.0), (0.01, 1e5), (0.02, 0.0), (0.03, 0.01)]]
[[False], [False], [False], [True]]
>>> g.rejected, g.velocity.round(3).tolist()   # two jumps refused; then 1 rad/s from rest again
(2, [0.27])
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

STILL = 1e-9  # units/s: a smaller velocity is rest (far below any sensor's resolution)
NAN = math.nan


class VelocityFilter:
    """``update(t, q)`` with ``n`` values at time ``t`` (s); ``velocity`` holds the estimates.

    ``max_rate`` (per signal, units/s; ``inf`` where unknown): a step implying a
    faster rate is refused. ``rejected`` counts the samples refused, ``refused``
    marks those of the last ``update``.

    The state is plain floats, one signal after the other: for the tens of signals of a
    robot, numpy's cost per call was most of the filter's (45 µs a frame for 17 joints,
    ~10 µs in a loop). ``step`` and ``values`` are the list face a processor uses;
    ``update``, ``velocity``, ``known`` and ``refused`` give numpy arrays (copies)."""

    def __init__(self, n: int, cutoff_hz: float, max_gap_s: float = 0.5, max_rate: np.ndarray | None = None) -> None:
        if not cutoff_hz > 0 or not max_gap_s > 0:
            raise ValueError(f"cut-off ({cutoff_hz} Hz) and max gap ({max_gap_s} s) must be more than 0")
        self.n, self.cutoff_hz, self.max_gap_s = n, cutoff_hz, max_gap_s
        self.tau = 1.0 / (2.0 * math.pi * cutoff_hz)
        self.max_rate = np.full(n, np.inf) if max_rate is None else np.asarray(max_rate, dtype=float)
        if self.max_rate.shape != (n,) or not (self.max_rate > 0).all():
            raise ValueError(f"max_rate must be {n} values more than 0")
        self._rates: list[float] = self.max_rate.tolist()
        self.values = [0.0] * n      # the velocities
        self.refusals: list[int] = []  # the signals refused by the last step, in order
        self.rejected = 0
        self._known = [False] * n    # has a velocity (and a step to take the slope from)
        self._last_q = [NAN] * n
        self._last_t = [NAN] * n
        self._last_r = [0.0] * n
        self._last_dt = [1.0] * n
        self._dt = NAN  # the last step's Δt, and its e and δ: a frame's signals share them
        self._e = self._delta = 0.0

    velocity = property(lambda self: np.array(self.values), doc="The velocities, an array (a copy).")
    known = property(lambda self: np.array(self._known), doc="Which signals have a velocity to go on from.")

    @property
    def refused(self) -> np.ndarray:
        """Which signals the last update refused (an array)."""
        marks = np.zeros(self.n, dtype=bool)
        marks[self.refusals] = True
        return marks

    def update(self, t: float, q: np.ndarray) -> np.ndarray:
        """Take the values ``q`` sampled at ``t``; returns which signals have a velocity for ``t``."""
        return np.array(self.step(t, q.tolist() if isinstance(q, np.ndarray) else list(q)), dtype=bool)

    def step(self, t: float, q: Sequence[float]) -> list[bool]:
        """``update`` with floats in and out: which signals have a velocity (``values``) for ``t``."""
        values, known, last_q, last_t, last_r, last_dt = (self.values, self._known, self._last_q, self._last_t,
                                                          self._last_r, self._last_dt)
        gap, tau = self.max_gap_s, self.tau
        step_dt, e, delta = self._dt, self._e, self._delta  # (the signals of a frame share their Δt)
        t = float(t)  # (a numpy scalar would make every velocity one)
        fresh = [False] * len(q)
        refusals: list[int] = []
        for i, (x, rate) in enumerate(zip(q, self._rates, strict=True)):
            if x - x != 0.0:  # not finite
                if x == x:  # ±inf: refused, and nothing to start over from
                    refusals.append(i)
                    values[i] = 0.0
                    known[i] = False
                    last_q[i] = last_t[i] = NAN
                continue  # (NaN is no sample: the signal keeps its state)
            dt = t - last_t[i]
            moved = x - last_q[i]
            if 0.0 < dt <= gap and abs(moved) <= rate * dt:
                if dt != step_dt:
                    step_dt = dt
                    e = math.exp(-dt / tau)
                    delta = dt / 2 - tau + dt * e / (1.0 - e) if e != 1.0 else math.inf
                r = moved / dt
                slope = (r - last_r[i]) / ((dt + last_dt[i]) / 2) if known[i] else 0.0
                v = e * values[i] + (1.0 - e) * (r + slope * delta)
                if v - v != 0.0:  # a rate beyond float, where max_rate is unknown: never kept
                    refusals.append(i)
                    values[i] = 0.0
                    known[i] = False
                    last_q[i] = last_t[i] = NAN
                    continue
                values[i] = v if abs(v) >= STILL else 0.0  # a decay to rest ends at rest, not at 1.9e-228
                known[i] = fresh[i] = True
                last_r[i] = r
                last_dt[i] = dt
            else:  # a first sample, one after a gap: start over from it; so too from a jump or time going back
                if dt < 0.0 or 0.0 < dt <= gap:
                    refusals.append(i)
                values[i] = 0.0
                known[i] = False
            last_q[i] = x
            last_t[i] = t
        self._dt, self._e, self._delta = step_dt, e, delta
        self.rejected += len(refusals)
        self.refusals = refusals
        return fresh

    def reset(self) -> None:
        """Forget everything: the next samples start over."""
        n = self.n
        self.values[:], self._known[:] = [0.0] * n, [False] * n
        self._last_q[:], self._last_t[:] = [NAN] * n, [NAN] * n
