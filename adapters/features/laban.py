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
import operator
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
    """``update(t, p, v, a, j)`` per frame with arrays (n, dim) of positions and their derivatives
    (``rows`` with the same as nested lists: what the node calls).

    The window's sums are kept running (added as a frame comes, taken off as it leaves, summed
    anew every ``RESUM`` frames so rounding cannot build up) and Weight's maximum in a
    monotonic queue per group: a frame costs the same whatever the window holds. A group's
    points are few (a hand; a chain's angles), so a frame is worked out in plain floats:
    numpy's cost per call is more than the arithmetic."""

    RESUM = 512

    def __init__(self, alpha: np.ndarray, window_s: float = 0.5, min_displacement: float | list[float] = 1e-3,
                 still: float = 0.05) -> None:
        """``min_displacement``: Space's floor, one for every group or one per group."""
        if not window_s > 0:
            raise ValueError(f"Laban window ({window_s} s) must be more than 0")
        alpha = np.asarray(alpha, dtype=float)
        self._single = alpha.ndim == 1  # one group: floats out
        self.alpha = alpha[None, :] if self._single else alpha
        # per group its points' (index, weight), those of weight 0 left out
        self._terms = [[(i, w) for i, w in enumerate(row) if w != 0] for row in self.alpha.tolist()]
        self._unit = self._terms == [[(g, 1.0)] for g in range(len(self._terms))]  # each group one point (the node's)
        self._mass = self.alpha.sum(axis=1).tolist()
        self.window_s, self.min_displacement, self.still = window_s, min_displacement, still
        self._floors = (list(min_displacement) if isinstance(min_displacement, list | tuple)
                        else [min_displacement] * len(self._terms))
        # per frame: t, its step (Δt, then per group Δt·mean Σα‖a‖, Δt·mean Σα‖j‖, Δt·mean Σα‖v‖,
        # path length), positions
        self._frames: deque[tuple[float, list[float], list[list[float]]]] = deque()
        self._sums = [0.0] * (1 + 4 * len(self._terms))  # of the steps of every frame in the window
        self._heaviest: list[deque[tuple[float, float]]] = [deque() for _ in self._terms]  # (t, Σα‖v‖²) falling
        self._norms: list[float] = []  # the last frame's Σα‖a‖, Σα‖j‖, Σα‖v‖ per group
        self._count = 0

    def update(self, t: float, p: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> Efforts:
        """The Efforts at frame ``t``."""
        rows = self.rows(t, *(np.asarray(x, dtype=float).tolist() for x in (p, v, a, j)))
        if self._single:
            return Efforts(*rows[0])
        return Efforts(*(np.array(column) for column in zip(*rows, strict=True)))

    def rows(self, t: float, p: list[list[float]], v: list[list[float]], a: list[list[float]],
             j: list[list[float]]) -> list[tuple[float, float, float, float, float]]:
        """Per group (weight, time, flow, space, fluidity) at frame ``t``, from each point's
        position and derivatives as lists of coordinates."""
        frames = self._frames
        if frames and not t > frames[-1][0]:
            frames.clear()
            for heaviest in self._heaviest:
                heaviest.clear()
            self._sums = [0.0] * len(self._sums)
        hypot = math.hypot
        speeds = [hypot(*x) for x in v]
        if self._unit:
            norms = [hypot(*x) for x in a] + [hypot(*x) for x in j] + speeds
        else:
            norms = (self._weighted([hypot(*x) for x in a]) + self._weighted([hypot(*x) for x in j])
                     + self._weighted(speeds))
        if frames:
            last_t, _, last_p = frames[-1]
            dt = t - last_t
            step = [dt] + [dt * (x + y) / 2 for x, y in zip(norms, self._norms, strict=True)]  # the step's mean
            step += self._distances(p, last_p)
        else:
            step = [0.0] * len(self._sums)
        self._norms = norms
        frames.append((t, step, p))
        sums = [x + y for x, y in zip(self._sums, step, strict=True)]
        while t - frames[0][0] > self.window_s * (1 + 1e-9):
            sums = [x - y for x, y in zip(sums, frames.popleft()[1], strict=True)]
        self._count += 1
        if self._count % self.RESUM == 0:
            sums = [math.fsum(column) for column in zip(*(f[1] for f in frames), strict=True)]
        self._sums = sums
        first_t, first_step, first_p = frames[0]
        span = sums[0] - first_step[0]  # (each step lies inside the window, the first frame's before it)
        inside = [x - y for x, y in zip(sums, first_step, strict=True)]  # each step lies inside the window
        groups, still = len(self._terms), self.still
        out = []
        for heaviest, w, d, floor, time_, flow, speed, path in zip(
                self._heaviest, self._weighted([x * x for x in speeds]), self._distances(p, first_p), self._floors,
                inside[1:1 + groups], inside[1 + groups:1 + 2 * groups], inside[1 + 2 * groups:1 + 3 * groups],
                inside[1 + 3 * groups:], strict=True):
            while heaviest and heaviest[-1][1] <= w:
                heaviest.pop()
            heaviest.append((t, w))
            while heaviest[0][0] < first_t:
                heaviest.popleft()
            space = path / d if d > floor else math.nan
            if span > 0:
                time_, flow, speed = time_ / span, flow / span, speed / span
                out.append((heaviest[0][1], time_, flow, space, speed / time_ if speed > still and time_ > 0
                            else math.nan))
            else:
                out.append((heaviest[0][1], math.nan, math.nan, space, math.nan))
        return out

    def _weighted(self, values: list[float]) -> list[float]:
        """Σ α_i x_i per group of the points' ``values``."""
        if self._unit:
            return values
        return [sum(w * values[i] for i, w in terms) for terms in self._terms]

    def _distances(self, p: list[list[float]], q: list[list[float]]) -> list[float]:
        """Σ α_i ‖p_i − q_i‖ / Σ α_i per group."""
        moved = [math.hypot(*map(operator.sub, pi, qi)) for pi, qi in zip(p, q, strict=True)]
        if self._unit:
            return moved
        return [x / m for x, m in zip(self._weighted(moved), self._mass, strict=True)]
