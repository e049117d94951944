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
    # (at most 1: a straight path's sum of steps can round below its displacement)
    return min(1.0, float(np.linalg.norm(points[-1] - points[0])) / path) if path > 0 else math.nan


def fluidity(t: np.ndarray, speed: np.ndarray, acc: np.ndarray) -> float:
    """⟨‖v‖⟩ / ⟨‖a‖⟩ time-weighted over the frames' own steps (s) (Burger et al. 2013)."""
    dt = np.diff(t)
    return float((speed[1:] * dt).sum() / (acc[1:] * dt).sum())


SEGMENT = ("duration_s", "pause_s", "path", "peak_speed", "directness", "fluidity", "sparc", "ldlj")
MIN_FRAMES = 5  # a shorter segment has no speed profile worth a SPARC or an LDLJ


class SegmentRecorder:
    """One chain's path frame by frame (``add``), cut into motion segments by its onset and
    offset (``change``, with the time the chain's QoM crossed the threshold, which the event
    confirms ``min_duration_s`` later). The segment an offset closes:

    - ``duration_s`` from onset to offset crossing; ``pause_s`` since the previous offset
      crossing (absent for a chain's first segment);
    - ``path`` Σ‖Δp‖ over the frames; ``directness`` displacement / path;
    - on the path resampled at the frames' median rate (linear), its speed by central
      differences: ``peak_speed``, ``fluidity`` ⟨‖v‖⟩/⟨‖a‖⟩, ``sparc`` and ``ldlj``.

    Values not defined (no path, too few frames) are left out."""

    def __init__(self, min_duration_s: float, max_s: float = 60.0) -> None:
        self.keep_s = 2 * min_duration_s + 0.2  # before an onset: enough to reach back to its crossing
        self.max_s = max_s                      # a motion longer than this keeps its last max_s
        self._times: list[float] = []
        self._points: list[list[float]] = []  # (lists: a frame's copy costs less than an array's)
        self._moving = False
        self._start: float | None = None
        self._last_offset: float | None = None

    def add(self, t: float, point: np.ndarray | list[float]) -> None:
        if self._times and not t > self._times[-1]:
            self._times.clear()
            self._points.clear()
        self._times.append(t)
        self._points.append(point.tolist() if isinstance(point, np.ndarray) else list(map(float, point)))
        horizon = t - (self.max_s if self._moving else self.keep_s)
        if self._times[0] < horizon - 1.0:  # trim in batches, not every frame
            cut = int(np.searchsorted(self._times, horizon))
            del self._times[:cut], self._points[:cut]

    def change(self, state: str, at: float) -> dict[str, float] | None:
        if state == "onset":
            self._moving, self._start = True, at
            return None
        self._moving = False
        start, self._start = self._start, None
        if start is None:
            return None
        times = np.array(self._times)
        inside = (times >= start - 1e-9) & (times <= at + 1e-9)
        out = {"duration_s": at - start}
        if self._last_offset is not None:
            out["pause_s"] = start - self._last_offset
        self._last_offset = at
        if inside.sum() >= 2:
            out.update(describe(times[inside], np.array([p for p, i in zip(self._points, inside, strict=True) if i])))
        return {k: float(v) for k, v in out.items() if math.isfinite(v)}


def describe(t: np.ndarray, points: np.ndarray) -> dict[str, float]:
    """A segment's path values from its frames' times ``t`` and points (n, dim)."""
    out = {"path": float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()), "directness": directness(points)}
    if len(t) < MIN_FRAMES:
        return out
    fs = 1.0 / float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1] + 0.5 / fs, 1.0 / fs)
    uniform = np.stack([np.interp(grid, t, points[:, k]) for k in range(points.shape[1])], axis=1)
    velocity = np.gradient(uniform, 1.0 / fs, axis=0)
    speed = np.linalg.norm(velocity, axis=1)
    if not speed.max() > 0:
        return out
    acc = np.linalg.norm(np.gradient(velocity, 1.0 / fs, axis=0), axis=1)
    return {**out, "peak_speed": float(speed.max()), "fluidity": fluidity(grid, speed, acc),
            "sparc": sparc(speed, fs), "ldlj": ldlj(speed, fs)}
