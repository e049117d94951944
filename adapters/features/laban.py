"""Larboulette & Gibet's (MOCO 2015) four Laban Efforts over a trailing window of
``T`` seconds, time-weighted so that the frame rate and skipped frames do not
change them.

Per frame k, with point weights α_i (1: per unit mass) and the window
W_T(k) = {m : t_k − T < t_m ≤ t_k}, Δt_m the frame's own step:

- Weight = max over W_T of Σ α_i ‖v_i‖²           (m²/s²)
- Time   = Σ α_i ⟨‖a_i‖⟩_T                        (m/s²)
- Flow   = Σ α_i ⟨‖j_i‖⟩_T                        (m/s³; its value is defined
  by the differentiator, ``kinematic.PointDerivatives``)
- Space  = L / d: path length over W_T divided by the displacement over it
  (none; NaN while d is under ``min_displacement``); directness is its inverse
- fluidity = ⟨Σ α_i ‖v_i‖⟩_T / ⟨Σ α_i ‖a_i‖⟩_T    (s; Burger et al. 2013's
  ``mcfluidity`` on a trailing window; NaN while ⟨‖v‖⟩ is under ``still``: a
  ratio of two noises says nothing)

⟨x⟩_T = Σ ½(x_m + x_(m−1)) Δt_m / Σ Δt_m over the steps inside the window
(the time-weighted mean, trapezoid rule: exact to second order in Δt however
unevenly frames are dropped).

With weights α of shape (G, n), G groups of the points are worked out at once
(the node's: each hand its own group, each joint chain one point of its
angles), and every Effort is an array of G values.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Efforts:
    """The four Efforts and fluidity of one frame (floats, or arrays of one per group); NaN
    where not defined yet."""

    weight: float | np.ndarray
    time: float | np.ndarray
    flow: float | np.ndarray
    space: float | np.ndarray
    fluidity: float | np.ndarray = math.nan


class LabanEfforts:
    """``update(t, p, v, a, j)`` per frame with arrays (n, dim) of positions and their derivatives.

    The window's sums are kept running (added as a frame comes, taken off as it leaves, summed
    anew every ``RESUM`` frames so rounding cannot build up) and Weight's maximum in a
    monotonic queue per group: a frame costs the same whatever the window holds."""

    RESUM = 512

    def __init__(self, alpha: np.ndarray, window_s: float = 0.5, min_displacement: float = 1e-3,
                 still: float = 0.05) -> None:
        if not window_s > 0:
            raise ValueError(f"Laban window ({window_s} s) must be more than 0")
        alpha = np.asarray(alpha, dtype=float)
        self._single = alpha.ndim == 1  # one group: floats out
        self.alpha = alpha[None, :] if self._single else alpha
        self._mass = self.alpha.sum(axis=1)
        self.window_s, self.min_displacement, self.still = window_s, min_displacement, still
        groups = len(self.alpha)
        # per frame: t, its step's (Δt, Δt·mean Σα‖a‖, Δt·mean Σα‖j‖, Δt·mean Σα‖v‖, path length) per group,
        # positions
        self._frames: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self._sums = np.zeros((5, groups))  # of the steps of every frame in the window
        self._heaviest: list[deque[tuple[float, float]]] = [deque() for _ in range(groups)]  # (t, Σα‖v‖²) falling
        self._norms = np.zeros((3, groups))  # the last frame's Σα‖a‖, Σα‖j‖, Σα‖v‖
        self._count = 0

    def _weighted(self, x: np.ndarray) -> np.ndarray:
        return self.alpha @ np.sqrt(np.einsum("ij,ij->i", x, x))

    def update(self, t: float, p: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> Efforts:
        """The Efforts at frame ``t``."""
        frames = self._frames
        if frames and not t > frames[-1][0]:
            frames.clear()
            for heaviest in self._heaviest:
                heaviest.clear()
            self._sums[:] = 0.0
        p = np.array(p, dtype=float)
        norms = np.stack([self._weighted(a), self._weighted(j), self._weighted(v)])
        step = np.zeros_like(self._sums)
        if frames:
            last_t, _, last_p = frames[-1]
            dt = t - last_t
            step[0] = dt
            step[1:4] = dt * (norms + self._norms) / 2  # the step's mean (trapezoid)
            step[4] = self._weighted(p - last_p) / self._mass
        self._norms = norms
        frames.append((t, step, p))
        self._sums += step
        while t - frames[0][0] > self.window_s * (1 + 1e-9):
            self._sums -= frames.popleft()[1]
        first = frames[0][0]
        weight = np.empty(len(self._heaviest))
        for g, (heaviest, w) in enumerate(zip(self._heaviest, (self.alpha @ np.einsum("ij,ij->i", v, v)).tolist(),
                                              strict=True)):
            while heaviest and heaviest[-1][1] <= w:
                heaviest.pop()
            heaviest.append((t, w))
            while heaviest[0][0] < first:
                heaviest.popleft()
            weight[g] = heaviest[0][1]
        self._count += 1
        if self._count % self.RESUM == 0:
            self._sums = np.sum([f[1] for f in frames], axis=0)
        span, acc, jerk, speed, path = self._sums - frames[0][1]  # each step lies inside the window
        groups = len(weight)
        if span[0] > 0:  # (the same Δt for every group)
            time_, flow, speed = acc / span[0], jerk / span[0], speed / span[0]
        else:
            time_ = flow = speed = np.full(groups, np.nan)
        d = self._weighted(p - frames[0][2]) / self._mass
        space = np.divide(path, d, out=np.full(groups, np.nan), where=d > self.min_displacement)
        fluidity = np.divide(speed, time_, out=np.full(groups, np.nan), where=(speed > self.still) & (time_ > 0))
        if self._single:
            return Efforts(float(weight[0]), float(time_[0]), float(flow[0]), float(space[0]), float(fluidity[0]))
        return Efforts(weight, time_, flow, space, fluidity)
