"""Audio on the bus: a robot's microphones on ``<robot>/audio/mic``, what it
should play on ``<robot>/audio/speaker``, as chunks of int16 PCM of about
10-20 ms (``schemas/v1/audio_chunk.json``; the gate checks them,
``bus/messages.py``). Publish them with ``node.AUDIO``; play them through a
``JitterBuffer`` (``bus/jitter.py``).

>>> import numpy as np
>>> chunk = AudioChunk.from_samples(1.5, 0, 16000, np.array([[0.5, -1.0], [0.0, 2.0]]))
>>> chunk.frames, chunk.samples().tolist()
(2, [[16384, -32767], [0, 32767]])
>>> AudioChunk.of(chunk.message()) == chunk
True
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .keys import Key
from .messages import Gate

__all__ = ["FULL_SCALE", "SAMPLE", "AudioChunk", "received", "to_int16"]

FULL_SCALE = 32767
SAMPLE = np.dtype("<i2")  # int16 little-endian, whatever this host's byte order


@dataclass(frozen=True)
class AudioChunk:
    """One chunk of audio: ``t`` (wall-clock s of its first sample), ``seq`` (+1 per
    chunk of its key), ``rate`` (Hz), ``channels`` and ``pcm`` (int16 little-endian,
    interleaved)."""

    t: float
    seq: int
    rate: int
    channels: int
    pcm: bytes

    @property
    def frames(self) -> int:
        return len(self.pcm) // (2 * self.channels)

    @property
    def duration(self) -> float:
        """Seconds of audio it holds."""
        return self.frames / self.rate

    def samples(self) -> np.ndarray:
        """The samples, int16 of shape (frames, channels) (a read-only view of ``pcm``)."""
        return np.frombuffer(self.pcm, SAMPLE).reshape(-1, self.channels)

    def message(self) -> dict[str, Any]:
        """The payload map (encode with ``bus.codec.encode``)."""
        return {"t": self.t, "seq": self.seq, "rate": self.rate, "channels": self.channels, "pcm": self.pcm}

    @classmethod
    def of(cls, message: dict[str, Any]) -> AudioChunk:
        """The chunk a gate-checked message carries."""
        return cls(float(message["t"]), message["seq"], message["rate"], message["channels"], message["pcm"])

    @classmethod
    def from_samples(cls, t: float, seq: int, rate: int, samples: np.ndarray) -> AudioChunk:
        """A chunk of ``samples``: int16 or float in [-1, 1] (clipped), shape (frames,
        channels) or (frames,) for one channel."""
        array = to_int16(samples)
        if array.ndim == 1:
            array = array[:, np.newaxis]
        if array.ndim != 2 or not array.size:
            raise ValueError(f"samples of shape {array.shape}: (frames, channels) with 1 frame at least expected")
        return cls(t, seq, rate, array.shape[1], array.astype(SAMPLE, copy=False).tobytes())


def to_int16(samples: np.ndarray) -> np.ndarray:
    """``samples`` as int16: int16 unchanged, float in [-1, 1] clipped and scaled to ±32767."""
    array = np.asarray(samples)
    if array.dtype.kind == "f":
        return np.rint(np.clip(array, -1.0, 1.0) * FULL_SCALE).astype(np.int16)
    if array.dtype != np.int16:
        raise TypeError(f"samples of dtype {array.dtype}: int16, or float in [-1, 1], expected")
    return array


def received(gate: Gate, key: str, payload: bytes, count: Callable[..., None],
             warn: Callable[[str, str], None]) -> AudioChunk | None:
    """The chunk that came on ``key``, checked by ``gate`` and counted by a node's
    ``count`` (``received``; ``bad``, ``warn``ed about): None if it is refused."""
    count("received")
    try:
        return AudioChunk.of(gate.check(Key.parse(key), payload))
    except ValueError as exc:  # messages.BadMessage, or a key that is not a data key
        count("bad")
        warn("bad", f"audio chunk on '{key}' refused: {exc}")
        return None
