"""Per-segment (onset → offset) smoothness of a speed profile: SPARC and LDLJ
(Balasubramanian, Melendez-Calderon, Roby-Brami & Burdet, JNER 2015, 12:112),
as in their reference code (github.com/siva82kb/SPARC) and monalysa 0.2.1; and
directness and fluidity of a path.

>>> import numpy as np
>>> t = np.arange(-1, 1, 0.01)
>>> round(sparc(np.exp(-5 * t**2), 100.0), 5), round(ldlj(np.exp(-5 * t**2), 100.0), 5)
(-1.41403, -5.81636)
"""

from __future__ import annotations

import math

import numpy as np


def sparc(speed: np.ndarray, fs: float, padlevel: int = 4, fc: float = 10.0, amp_th: float = 0.05) -> float:
    """Spectral arc length of a uniformly sampled speed profile (≤ 0; about −1.4 for a smooth reach)."""
    nfft = int(2 ** (math.ceil(math.log2(len(speed))) + padlevel))
    f = np.arange(0, fs, fs / nfft)
    mf = np.abs(np.fft.fft(speed, nfft))
    mf = mf / mf.max()
    inx = np.nonzero(f <= fc)[0]
    f_sel, mf_sel = f[inx], mf[inx]
    above = np.nonzero(mf_sel >= amp_th)[0]
    fc_inx = range(above[0], above[-1] + 1)
    f_sel, mf_sel = f_sel[fc_inx], mf_sel[fc_inx]
    return -float(np.sum(np.sqrt((np.diff(f_sel) / (f_sel[-1] - f_sel[0])) ** 2 + np.diff(mf_sel) ** 2)))


def ldlj(speed: np.ndarray, fs: float) -> float:
    """Log dimensionless jerk of a uniformly sampled speed profile (reference code's form)."""
    dt = 1.0 / fs
    duration = len(speed) * dt
    jerk = np.diff(speed, 2) / dt**2
    return -math.log((duration**3 / np.max(np.abs(speed)) ** 2) * float(np.sum(jerk**2)) * dt)


def directness(points: np.ndarray) -> float:
    """Displacement over path length of a sampled path (n, 3), in [0, 1]; NaN with no path."""
    path = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    return float(np.linalg.norm(points[-1] - points[0])) / path if path > 0 else math.nan


def fluidity(t: np.ndarray, speed: np.ndarray, acc: np.ndarray) -> float:
    """⟨‖v‖⟩ / ⟨‖a‖⟩ time-weighted over the frames' own steps (s) (Burger et al. 2013)."""
    dt = np.diff(t)
    return float((speed[1:] * dt).sum() / (acc[1:] * dt).sum())
