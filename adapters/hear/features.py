"""Audio features of one chunk, pure numpy (no clocks, no bus): loudness as RMS in dB
full scale, the spectral centroid in Hz, and onsets from the loudness's jump over the chunk
before.

Why numpy and not a library: librosa (the usual choice) pulls numba and scipy in for
three formulas of a few lines each, computed here on 10-20 ms chunks as they come;
aubio's last release (0.4.9, 2019) is a source package that needs a compiler. Each is a closed form, tested as one
(tests/hear/test_features.py): a sine of amplitude ``A`` is ``20·log10(A/√2)`` dB, a
sine of ``f`` Hz has its centroid at ``f``, an impulse in silence is an onset.

>>> import numpy as np
>>> n = np.arange(480)
>>> sine = 0.5 * np.sin(2 * np.pi * 1000 * n / 48000)   # ten whole periods
>>> round(level_db(sine), 2), round(centroid_hz(sine, 48000))
(-9.03, 1000)
"""

from __future__ import annotations

import math

import numpy as np

FLOOR_DB = -100.0  # the quietest level told (digital silence is -inf dB: it is said as this)


def level_db(samples: np.ndarray) -> float:
    """The RMS level of ``samples`` (floats, full scale ±1, any shape: every channel
    counts) in dB full scale, at least ``FLOOR_DB``."""
    power = float(np.mean(np.square(samples, dtype=np.float64))) if samples.size else 0.0
    return max(FLOOR_DB, 10.0 * math.log10(power)) if power > 0.0 else FLOOR_DB


def centroid_hz(samples: np.ndarray, rate: int) -> float:
    """The spectral centroid of ``samples`` (frames, or frames × channels): the mean of the
    frequencies weighted by their magnitude, Hann-windowed; 0 for silence."""
    frames = samples if samples.ndim == 1 else samples.reshape(len(samples), -1)
    if len(frames) < 2:
        return 0.0
    window = np.hanning(len(frames))
    spectrum = np.abs(np.fft.rfft(frames * (window if frames.ndim == 1 else window[:, None]), axis=0))
    if spectrum.ndim > 1:
        spectrum = spectrum.sum(axis=1)
    total = float(spectrum.sum())
    if not total > 0.0:
        return 0.0
    return float(np.dot(np.fft.rfftfreq(len(frames), 1.0 / rate), spectrum) / total)


class Onsets:
    """Onsets by level: a chunk ``jump_db`` louder than the chunk before it (the floor
    after a silence), and at least ``min_db``, is an onset; another cannot come within
    ``hold_s`` (a clap's reverberation is not a second clap). A steady or slowly rising
    sound is no onset, whatever its level.

    >>> onsets = Onsets()
    >>> [onsets(t / 100, db) for t, db in enumerate([-80, -80, -20, -22, -80, -80])]
    [False, False, True, False, False, False]
    """

    def __init__(self, jump_db: float = 12.0, min_db: float = -50.0, hold_s: float = 0.15) -> None:
        self.jump_db, self.min_db, self.hold_s = jump_db, min_db, hold_s
        self.before = FLOOR_DB          # the level of the chunk before
        self._onset_t = -math.inf

    def __call__(self, t: float, db: float) -> bool:
        """Whether the chunk at ``t`` (s) of level ``db`` is an onset."""
        onset = db >= self.min_db and db - self.before >= self.jump_db and t - self._onset_t >= self.hold_s
        if onset:
            self._onset_t = t
        self.before = db
        return onset

    def quiet(self) -> None:
        """No sound came (a sender that sends no digital silence): the chunk before is silence."""
        self.before = FLOOR_DB
