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
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Efforts:
    """The four Efforts of one frame; NaN where not defined yet."""

    weight: float
    time: float
    flow: float
    space: float
    fluidity: float = math.nan


class LabanEfforts:
    """``update(t, p, v, a, j)`` per frame with arrays (n, 3) of positions and their derivatives."""

    def __init__(self, alpha: np.ndarray, window_s: float = 0.5, min_displacement: float = 1e-3,
                 still: float = 0.05) -> None:
        if not window_s > 0:
            raise ValueError(f"Laban window ({window_s} s) must be more than 0")
        self.alpha = np.asarray(alpha, dtype=float)
        self.window_s, self.min_displacement, self.still = window_s, min_displacement, still
        # per frame: t, Δt, Σα‖v‖², Σα‖a‖, Σα‖j‖, Σα‖v‖, positions, path length of its step
        self._norms = [0.0, 0.0, 0.0]  # the last frame's Σα‖a‖, Σα‖j‖, Σα‖v‖
        self._frames: deque[tuple[float, float, float, float, float, float, np.ndarray, float]] = deque()

    def update(self, t: float, p: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> Efforts:
        """The Efforts at frame ``t``."""
        last = self._frames[-1] if self._frames else None
        if last is not None and not t > last[0]:
            self._frames.clear()
            last = None
        dt = t - last[0] if last is not None else 0.0
        step = float(self.alpha @ np.linalg.norm(p - last[6], axis=1)) / self.alpha.sum() if last is not None else 0.0
        norms = [float(self.alpha @ np.linalg.norm(x, axis=1)) for x in (a, j, v)]
        previous, self._norms = (self._norms if last is not None else norms), norms
        norms = [(x + y) / 2 for x, y in zip(norms, previous, strict=True)]  # the step's mean (trapezoid)
        self._frames.append((t, dt, float(self.alpha @ np.einsum("ij,ij->i", v, v)), *norms, np.array(p), step))
        while t - self._frames[0][0] > self.window_s * (1 + 1e-9):
            self._frames.popleft()
        span = sum(f[1] for f in list(self._frames)[1:])
        inner = list(self._frames)[1:]  # each step lies inside the window
        time_ = sum(f[1] * f[3] for f in inner) / span if span > 0 else math.nan
        flow = sum(f[1] * f[4] for f in inner) / span if span > 0 else math.nan
        speed = sum(f[1] * f[5] for f in inner) / span if span > 0 else math.nan
        path = sum(f[7] for f in inner)
        first = self._frames[0][6]
        d = float(self.alpha @ np.linalg.norm(np.asarray(p) - first, axis=1)) / self.alpha.sum()
        space = path / d if d > self.min_displacement else math.nan
        fluidity = speed / time_ if speed > self.still and time_ > 0 else math.nan
        return Efforts(max(f[2] for f in self._frames), time_, flow, space, fluidity)
