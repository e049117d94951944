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

import numpy as np

STILL = 1e-9  # units/s: a smaller velocity is rest (far below any sensor's resolution)


class VelocityFilter:
    """``update(t, q)`` with ``n`` values at time ``t`` (s); ``velocity`` holds the estimates.

    ``max_rate`` (per signal, units/s; ``inf`` where unknown): a step implying a
    faster rate is refused. ``rejected`` counts the samples refused, ``refused``
    marks those of the last ``update``."""

    def __init__(self, n: int, cutoff_hz: float, max_gap_s: float = 0.5, max_rate: np.ndarray | None = None) -> None:
        if not cutoff_hz > 0 or not max_gap_s > 0:
            raise ValueError(f"cut-off ({cutoff_hz} Hz) and max gap ({max_gap_s} s) must be more than 0")
        self.cutoff_hz, self.max_gap_s = cutoff_hz, max_gap_s
        self.tau = 1.0 / (2.0 * math.pi * cutoff_hz)
        self.max_rate = np.full(n, np.inf) if max_rate is None else np.asarray(max_rate, dtype=float)
        if self.max_rate.shape != (n,) or not (self.max_rate > 0).all():
            raise ValueError(f"max_rate must be {n} values more than 0")
        self.velocity = np.zeros(n)
        self.known = np.zeros(n, dtype=bool)  # has a velocity (and a step to take the slope from)
        self.rejected = 0
        self._none = np.zeros(n, dtype=bool)
        self._none.flags.writeable = False
        self.refused = self._none
        self._last_q = np.full(n, np.nan)
        self._last_t = np.full(n, np.nan)
        self._last_r = np.zeros(n)
        self._last_dt = np.ones(n)

    def update(self, t: float, q: np.ndarray) -> np.ndarray:
        """Take the values ``q`` sampled at ``t``; returns which signals have a velocity for ``t``."""
        dt = t - self._last_t
        finite = np.isfinite(q)
        with np.errstate(invalid="ignore", over="ignore"):
            due = finite & (dt > 0) & (dt <= self.max_gap_s)
            step = due & (np.abs(q - self._last_q) <= self.max_rate * dt)
        refused = self._none
        if step.all():  # the usual frame: no boolean indexing, nothing refused
            self._step(slice(None), dt, q)
        else:
            with np.errstate(invalid="ignore"):
                refused = (due & ~step) | (finite & (dt < 0)) | np.isinf(q)  # a jump, time going back, inf
            if step.any():
                self._step(step, dt[step], q[step])
        spoiled = None
        if not math.isfinite(self.velocity.sum()):  # a rate beyond float, where max_rate is unknown
            spoiled = ~np.isfinite(self.velocity)
            step = step & ~spoiled
            refused = refused | spoiled
        if refused is not self._none or not step.all():
            start = (finite | refused) & ~step
            self.velocity[start] = 0.0
            self.known[start] = False
        np.copyto(self._last_q, q, where=finite)
        np.copyto(self._last_t, t, where=finite)
        if refused is not self._none and refused.any():
            gone = refused & (~finite if spoiled is None else ~finite | spoiled)  # nothing to start over from
            self._last_q[gone] = self._last_t[gone] = np.nan
            self.rejected += int(np.count_nonzero(refused))
        self.refused = refused
        return step

    def _step(self, step: np.ndarray | slice, dt: np.ndarray, q: np.ndarray) -> None:
        with np.errstate(over="ignore", invalid="ignore"):  # (what overflows is caught by update)
            r = (q - self._last_q[step]) / dt
            e = np.exp(-dt / self.tau)
            delta = dt / 2 - self.tau + dt * e / (1.0 - e)
            slope = np.where(self.known[step], (r - self._last_r[step]) / ((dt + self._last_dt[step]) / 2), 0.0)
            v = e * self.velocity[step] + (1.0 - e) * (r + slope * delta)
            v[np.abs(v) < STILL] = 0.0  # a decay to rest ends at rest, not at 1.9e-228 in a CSV
            self.velocity[step] = v
        self.known[step] = True
        self._last_r[step], self._last_dt[step] = r, dt

    def reset(self) -> None:
        """Forget everything: the next samples start over."""
        self.velocity[:] = 0.0
        self.known[:] = False
        self._last_q[:] = self._last_t[:] = np.nan
