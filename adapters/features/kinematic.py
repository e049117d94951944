"""Velocity, acceleration and jerk of FK points from a causal local polynomial fit.

Each ``update(t, points)`` fits, per coordinate, a polynomial of degree
``degree`` (5 by default) in ``(t_m − t_k) / W`` by least squares to the samples
of the trailing window ``t_k − W < t_m ≤ t_k`` (``W = window_s``, by
default 0.4 s) and reads the fit and its derivatives at the window's middle,
``W/2`` before the newest frame (``time``): a Savitzky–Golay fit on the frames'
own times, causal with a lag of W/2 (0.2 s; three 3 Hz low-passes lag about as
much). A skipped frame is a missing row, not a wrong derivative, and the
estimate does not depend on the frame rate: on a 0.5 Hz circle of 0.2 m the
speed is within 2e-6, |a| and |j| within 2.5e-4 of the closed form at 50 and
100 Hz. Read at the newest frame instead, the same fit amplifies 1 mrad of
joint noise 7× more in jerk (and a degree-3 fit misreads |a| by 4 %): the
middle is the one reading that passes both.
The estimator and its window are part of the definition of every value derived
from ``a`` and ``j`` (Laban Time and Flow): they are published with them.

>>> import numpy as np
>>> d = PointDerivatives(1, window_s=0.4)
>>> for k in range(30):
...     fitted = d.update(k / 50, np.array([[0.1 * k / 50, 0.0, 0.0]]))
>>> bool(np.abs(d.velocity - [[0.1, 0.0, 0.0]]).max() < 1e-9), d.ready
(True, True)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.polynomial import legendre

SAME_TIMES = 1e-6  # window fractions: times closer than this (0.4 µs in 0.4 s) count as the same
STILL_SPEED = 0.05  # m/s: below, no curvature nor a_t, a_n (1 mrad of joint noise reads up to 0.01 m/s)


class FitOperator:
    """The linear map from a window's samples to (position, v, a, j) at its middle, for
    sample times ``s`` (fractions of the window, in (−1, 0]), kept for the last few time
    patterns: at a steady rate the same operator serves frame after frame.

    The fit is by least squares in the shifted Legendre basis of ``x = 2s + 1``: its 6×6 Gram
    matrix G is well conditioned, so its inverse is as exact as a pseudo-inverse of the power
    basis. Frames that come at their own times (a robot's clock) make a new operator each frame,
    and G then differs from the last frame's by the jitter: G⁻¹ is refined from the last one by
    Newton–Schulz steps (X ← X + X(I − GX), each squaring the error) to where ‖I − GX‖ is at
    rounding level, with only products of small arrays. On a node's worker thread (whose caches
    other threads cool between frames) ``np.linalg.inv`` and ``np.vander`` cost ~35 µs a frame
    more than these steps, though they run fewer instructions (two expressive nodes side by side
    on one bus, 3 runs: 1.53 vs 1.46× a default node's CPU)."""

    KEEP = 4  # time patterns kept (a steady rate alternates between two window lengths)
    EXACT = 1e-14  # a bound on ‖I − GX‖∞ after the steps: rounding level (G's condition number is ~10)
    CONVERGES = 0.5  # the bound n · max |I − GX| under this: the steps start (else an inverse from scratch)

    def __init__(self, window_s: float, degree: int = 5) -> None:
        eye = np.eye(degree + 1)
        self.degree = degree
        basis = np.zeros((degree + 1, degree + 1))  # powers of x → Legendre polynomials
        for k in range(degree + 1):
            c = legendre.leg2poly(eye[k])
            basis[:len(c), k] = c
        self._basis = basis.T.copy()  # (Legendre, power)
        # d^m/dt^m of each P_k(2s + 1) at the middle (s = −½, x = 0): P_k^(m)(0) (2/W)^m
        self._read = np.array([[legendre.legval(0.0, legendre.legder(eye[k], m)) * (2.0 / window_s) ** m
                                for k in range(degree + 1)] for m in range(4)])
        self._eye = eye
        self._inverses: dict[int, np.ndarray] = {}  # the last G⁻¹ per window length (frames)
        self._kept: list[tuple[np.ndarray, float, np.ndarray]] = []  # (s, s[0], operator), the last used first

    def __call__(self, s: np.ndarray) -> np.ndarray:
        """The operator (4, len(s)) for sample times ``s``."""
        first, frames = float(s[0]), len(s)
        for i, (known, known_first, operator) in enumerate(self._kept):
            # (the oldest frame's time first: frames that come at their own times miss on it, cheaply)
            if (len(known) == frames and abs(first - known_first) <= SAME_TIMES
                    and np.abs(s - known).max() <= SAME_TIMES):
                if i:
                    self._kept.insert(0, self._kept.pop(i))
                return operator
        x = 2.0 * s + 1.0
        powers = np.empty((self.degree + 1, len(s)))
        powers[0] = 1.0
        powers[1] = x
        for k in range(2, self.degree + 1):
            np.multiply(powers[k - 1], x, out=powers[k])
        v = self._basis @ powers  # (Legendre, sample)
        gram = v @ v.T
        operator = (self._read @ self._inverted(gram, len(s))) @ v
        self._kept.insert(0, (s, first, operator))
        del self._kept[self.KEEP:]
        return operator

    def _inverted(self, gram: np.ndarray, frames: int) -> np.ndarray:
        """G⁻¹ of a window of ``frames`` frames, from the last one of as many frames by
        Newton–Schulz steps where they reach rounding level."""
        inverse = self._inverses.get(frames)
        if inverse is not None:
            residual = self._eye - gram @ inverse
            bound = len(gram) * float(np.abs(residual).max())  # ≥ ‖I − GX‖∞, which each step squares
            if bound < self.CONVERGES:
                # as many steps as take the bound under EXACT (the last residual is not needed)
                steps = math.ceil(math.log2(math.log(self.EXACT) / math.log(bound))) if bound > self.EXACT else 0
                for step in range(steps):
                    inverse = inverse + inverse @ residual
                    if step < steps - 1:
                        residual = residual @ residual  # (I − G X') = (I − G X)²
                self._inverses[frames] = inverse
                return inverse
        if len(self._inverses) >= self.KEEP and frames not in self._inverses:
            self._inverses.pop(next(iter(self._inverses)))
        self._inverses[frames] = inverse = np.linalg.inv(gram)
        return inverse


class PointDerivatives:
    """Derivatives of ``n`` points of ``dim`` coordinates (3-D by default; 1 for joint
    angles), ``update(t, points)`` with ``points`` of shape (n, dim); ``derivatives`` stacks
    ``position``, ``velocity``, ``acceleration`` and ``jerk`` (4, n, dim)."""

    def __init__(self, n: int, window_s: float = 0.4, degree: int = 5, dim: int = 3) -> None:
        if not window_s > 0 or degree < 3:
            raise ValueError(f"window ({window_s} s) must be more than 0 and degree ({degree}) at least 3 for jerk")
        self.n, self.window_s, self.degree, self.dim = n, window_s, degree, dim
        # the window's frames, oldest first, at rows [_first, _end) of a buffer moved back when full
        self._t = np.zeros(64)
        self._y = np.zeros((64, n * dim))
        self._first = self._end = 0
        self._last_t = 0.0
        self.derivatives = np.zeros((4, n, dim))  # position, velocity, acceleration, jerk
        self.time = 0.0  # the time the derivatives are read at: the window's middle, window_s/2 ago
        self.ready = False  # True once the window holds enough frames for the fit
        # the fit is linear in the samples: (position, v, a, j) = operator @ samples, the operator
        # depending only on the frames' times in the window
        self._operator = FitOperator(window_s, degree)

    def update(self, t: float, points: np.ndarray) -> bool:
        """Add the frame at ``t``; ``True`` when the derivatives were estimated from it.
        A time that does not advance starts the window over."""
        first, end = self._first, self._end
        if end > first and not t > self._last_t:
            first = end = 0
        self._last_t = t
        if end == len(self._t):  # full: move the window to the front (or grow)
            count = end - first
            if count > len(self._t) // 2:
                self._t = np.concatenate([self._t, np.zeros_like(self._t)])
                self._y = np.concatenate([self._y, np.zeros_like(self._y)])
            self._t[:count], self._y[:count] = self._t[first:end], self._y[first:end]
            first, end = 0, count
        times = self._t
        times[end] = t
        self._y[end] = points.reshape(-1)
        end += 1
        oldest = float(times[first])
        while t - oldest > self.window_s * (1 + 1e-9):  # t_k − W < t_m ≤ t_k
            first += 1
            oldest = float(times[first])
        self._first, self._end = first, end
        # enough frames, spanning most of the window: a fit of a few first frames is mostly noise
        self.ready = end - first > self.degree + 1 and t - oldest >= 0.75 * self.window_s
        if not self.ready:
            return False
        operator = self._operator((times[first:end] - t) / self.window_s)
        self.derivatives = (operator @ self._y[first:end]).reshape(4, self.n, self.dim)
        self.time = t - self.window_s / 2
        return True

    # views on demand (unpacking four views a frame cost more than the reads)
    position = property(lambda self: self.derivatives[0], doc="The fitted positions (n, dim) at ``time``.")
    velocity = property(lambda self: self.derivatives[1], doc="The velocities (n, dim) at ``time``.")
    acceleration = property(lambda self: self.derivatives[2], doc="The accelerations (n, dim) at ``time``.")
    jerk = property(lambda self: self.derivatives[3], doc="The jerks (n, dim) at ``time``.")


def curvature(v: list[float], a: list[float], still: float = STILL_SPEED) -> float:
    """``geometry``'s κ of one point in plain floats (what a frame of two hands needs): NaN
    where ‖v‖ ≤ ``still``."""
    speed = math.hypot(*v)
    if not speed > still:
        return math.nan
    return math.hypot(v[1] * a[2] - v[2] * a[1], v[2] * a[0] - v[0] * a[2], v[0] * a[1] - v[1] * a[0]) / speed**3


def geometry(v: np.ndarray, a: np.ndarray, still: float = STILL_SPEED) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Curvature κ = ‖v × a‖/‖v‖³ (1/m), tangential a_t = v·a/‖v‖ and normal
    a_n = ‖v × a‖/‖v‖ acceleration (m/s²) per point; NaN where ‖v‖ ≤ ``still``."""
    speed = np.sqrt(np.einsum("...i,...i", v, v))
    c = np.stack([v[..., 1] * a[..., 2] - v[..., 2] * a[..., 1], v[..., 2] * a[..., 0] - v[..., 0] * a[..., 2],
                  v[..., 0] * a[..., 1] - v[..., 1] * a[..., 0]], axis=-1)  # v × a (np.cross costs 5× more)
    cross = np.sqrt(np.einsum("...i,...i", c, c))
    moving = speed > still
    safe = np.where(moving, speed, 1.0)
    nan = np.full_like(speed, np.nan)
    return (np.where(moving, cross / safe**3, nan), np.where(moving, np.einsum("...i,...i", v, a) / safe, nan),
            np.where(moving, cross / safe, nan))
