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
from collections import deque

import numpy as np

SAME_TIMES = 1e-6  # window fractions: times closer than this (0.4 µs in 0.4 s) count as the same
STILL_SPEED = 0.05  # m/s: below, no curvature nor a_t, a_n (1 mrad of joint noise reads up to 0.01 m/s)


class PointDerivatives:
    """Derivatives of ``n`` points of ``dim`` coordinates (3-D by default; 1 for joint
    angles), ``update(t, points)`` with ``points`` of shape (n, dim)."""

    def __init__(self, n: int, window_s: float = 0.4, degree: int = 5, dim: int = 3) -> None:
        if not window_s > 0 or degree < 3:
            raise ValueError(f"window ({window_s} s) must be more than 0 and degree ({degree}) at least 3 for jerk")
        self.n, self.window_s, self.degree, self.dim = n, window_s, degree, dim
        self._times: deque[float] = deque()
        self._points: deque[np.ndarray] = deque()
        self.position = np.zeros((n, dim))
        self.time = 0.0  # the time the derivatives are read at: the window's middle, window_s/2 ago
        self.velocity = np.zeros((n, dim))
        self.acceleration = np.zeros((n, dim))
        self.jerk = np.zeros((n, dim))
        self.ready = False  # True once the window holds enough frames for the fit
        # the fit is linear in the samples: (position, v, a, j) = operator @ samples, the operator
        # depending only on the frames' times in the window; at a steady rate it is the same frame
        # after frame, and is kept (a least-squares solve per frame cost 4× more)
        w = window_s
        self._read = np.array([[math.perm(k, m) * (-0.5) ** (k - m) / w**m if k >= m else 0.0
                                for k in range(degree + 1)] for m in range(4)])  # at s = −½, the middle
        self._s: np.ndarray | None = None
        self._operator = np.zeros((4, 0))

    def update(self, t: float, points: np.ndarray) -> bool:
        """Add the frame at ``t``; ``True`` when the derivatives were estimated from it.
        A time that does not advance starts the window over."""
        if self._times and not t > self._times[-1]:
            self._times.clear()
            self._points.clear()
        self._times.append(t)
        self._points.append(np.asarray(points, dtype=float).reshape(self.n, self.dim))
        while t - self._times[0] > self.window_s * (1 + 1e-9):  # t_k − W < t_m ≤ t_k
            self._times.popleft()
            self._points.popleft()
        # enough frames, spanning most of the window: a fit of a few first frames is mostly noise
        self.ready = len(self._times) > self.degree + 1 and t - self._times[0] >= 0.75 * self.window_s
        if not self.ready:
            return False
        s = (np.fromiter(self._times, float) - t) / self.window_s
        if self._s is None or len(s) != len(self._s) or np.abs(s - self._s).max() > SAME_TIMES:
            self._s, self._operator = s, self._read @ np.linalg.pinv(np.vander(s, self.degree + 1, increasing=True))
        out = (self._operator @ np.stack(self._points).reshape(len(s), -1)).reshape(4, self.n, self.dim)
        self.time = t - self.window_s / 2
        self.position, self.velocity, self.acceleration, self.jerk = out
        return True


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
