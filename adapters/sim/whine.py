"""The simulated robot's body sound: a servo whine per moving joint (numpy only).

Each joint that moves sings a band-limited sawtooth buzz whose pitch rises with
its speed (``BASE_HZ`` + a few Hz per joint + ``HZ_PER_RAD_S`` · |speed|) and
whose level follows |speed| relative to the joint's maximum velocity
(robots.json), plus a little gear noise. Level and pitch glide (one-pole
smoothing), so a joint starting or stopping makes no click; at rest only a
faint noise floor remains. Phase is kept across calls; the same seed and the
same calls give the same samples.

>>> whine = Whine(16000, 1)
>>> quiet = whine.render(320, {})
>>> loud = [whine.render(320, {"HeadYaw": 3.0}) for _ in range(10)][-1]
>>> int(abs(quiet).max()) < 50 < int(abs(loud).max())
True
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from sonibus.bus.audio import to_int16
from sonibus.bus.robot import RobotModel, load_model

BASE_HZ = 180.0          # a joint's pitch just above rest
SPREAD_HZ = 60.0         # joints differ by up to this, so two moving joints beat rather than merge
HZ_PER_RAD_S = 120.0     # pitch rise per rad/s of speed
HARMONICS = 16           # of the sawtooth, at most (fewer when they would pass Nyquist)
LEVEL_TAU_S = 0.02       # level glide: no click when a joint starts or stops
PITCH_TAU_S = 0.05       # pitch glide
DEFAULT_MAX_SPEED = 5.0  # rad/s, for a joint the model does not know


@dataclass
class _Voice:
    """One joint's oscillator state."""

    base_hz: float
    max_speed: float
    phase: float = 0.0
    level: float = 0.0
    hz: float = 0.0


def _glide(start: float, target: float, frames: int, tau_frames: float) -> np.ndarray:
    """One-pole approach from ``start`` to ``target``, sample by sample (closed form)."""
    decay = np.exp(-np.arange(1, frames + 1) / tau_frames)
    return target + (start - target) * decay


class Whine:
    """Servo whine synthesizer: ``render(frames, speeds)`` → int16 ``(frames, channels)``.

    ``speeds`` maps joint names to their speed now (rad/s, sign ignored); a joint
    left out is at rest. ``gain`` is the level of one joint at full speed
    (fraction of full scale), ``grit`` the gear noise relative to the motors'
    level, ``floor`` the noise floor's amplitude."""

    def __init__(self, rate: int, channels: int, *, model: str | RobotModel = "pepper", seed: int = 0,
                 gain: float = 0.25, grit: float = 0.15, floor: float = 2e-4) -> None:
        if not 8000 <= rate <= 192000:
            raise ValueError(f"rate {rate} Hz must be in 8000..192000")
        if not 1 <= channels <= 8:
            raise ValueError(f"channels {channels} must be in 1..8")
        self.rate, self.channels = rate, channels
        self.model = load_model(model) if isinstance(model, str) else model
        self.gain, self.grit, self.floor = gain, grit, floor
        self._seed = seed
        self._rng = np.random.default_rng(seed)
        self._voices: dict[str, _Voice] = {}

    def render(self, frames: int, speeds: Mapping[str, float]) -> np.ndarray:
        """The next ``frames`` samples while the joints move at ``speeds``."""
        if frames < 1:
            raise ValueError(f"frames {frames} must be 1 or more")
        for name in speeds:
            if name not in self._voices:
                self._voices[name] = self._voice(name)
        mono = np.zeros(frames)
        loudness = np.zeros(frames)
        for name, voice in list(self._voices.items()):
            speed = abs(float(speeds.get(name, 0.0)))
            level = self._advance(voice, speed, frames)
            if level is None:
                del self._voices[name]  # silent and at rest: forget it
                continue
            mono += level[0]
            loudness += level[1]
        grit = self.grit * loudness * self._rng.standard_normal(frames)  # gears: noise that follows the motors
        mono = np.tanh(mono + grit)  # many joints at once saturate softly instead of wrapping
        out = mono[:, None] + self.floor * self._rng.uniform(-1.0, 1.0, (frames, self.channels))
        return to_int16(out)

    def reset(self) -> None:
        """Back to silence and the seed's first noise."""
        self._voices.clear()
        self._rng = np.random.default_rng(self._seed)

    def _voice(self, name: str) -> _Voice:
        spec = self.model.joint(name) if self.model.has_joint(name) else None
        offset = (zlib.crc32(f"{self._seed}:{name}".encode()) % 1000) / 1000.0 * SPREAD_HZ
        max_speed = spec.max_velocity if spec is not None and spec.max_velocity > 0 else DEFAULT_MAX_SPEED
        return _Voice(base_hz=BASE_HZ + offset, max_speed=max_speed, hz=BASE_HZ + offset)

    def _advance(self, voice: _Voice, speed: float, frames: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The voice's samples and level for this block, or None once it is silent at rest."""
        target = self.gain * min(1.0, speed / voice.max_speed)
        if target == 0.0 and voice.level < 1e-5:
            return None
        level = _glide(voice.level, target, frames, LEVEL_TAU_S * self.rate)
        hz = _glide(voice.hz, voice.base_hz + HZ_PER_RAD_S * speed, frames, PITCH_TAU_S * self.rate)
        phase = voice.phase + np.cumsum(2 * np.pi * hz / self.rate)
        voice.level, voice.hz, voice.phase = float(level[-1]), float(hz[-1]), float(phase[-1] % (2 * np.pi))
        nyquist = self.rate / 2
        saw = np.zeros(frames)
        for k in range(1, HARMONICS + 1):
            # each harmonic fades out as it nears Nyquist instead of folding back
            fade = np.clip((0.9 * nyquist - k * hz) / (0.1 * nyquist), 0.0, 1.0)
            if not fade.any():
                break
            saw += fade * np.sin(k * phase) / k
        return level * saw * (2 / np.pi), level
