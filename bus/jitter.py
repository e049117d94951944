"""``JitterBuffer``: audio chunks in as they come (any thread), a steady stream out,
as many frames as a speaker or a JACK port asks for.

It converts each chunk to its own rate (soxr, one stream per sender's rate so
there are no seams between chunks; a lost chunk, a new rate or a sender that
restarted fades the old stream out and starts a new one, with silence for what
the old one still held) and channel count (down by the mean, up by copying).
Playback starts once ``target_ms`` is buffered. A chunk missing by
``seq`` plays as silence of its length; a chunk whose ``seq`` goes back comes
too late and is dropped (a sender that restarted, ``seq`` back but ``t``
ahead, is taken as a new stream). Running dry plays silence; more than
``max_ms`` buffered drops the oldest, down to ``target_ms``. Every edge
between sound and silence is faded over ``FADE_S``, and a cut is a crossfade,
so none clicks. ``ceiling`` is the loudest the output may be (a fraction of full
scale): samples are scaled by it, so nothing is distorted.

Two sound clocks never run at exactly one rate (a JACK card's and a robot's, or
wall-clock pacing): a fixed buffer then runs dry or over every so often. While
playing, the buffer follows the drift: when its level, averaged over
``LEVEL_TAU_S``, stays out of ``DEADBAND`` around target, it plays slightly faster
or slower (linear interpolation, at most ``follow_drift``, 0.5 % by default:
under a tenth of a semitone), so the level comes back instead of running out.
Within the dead band nothing is touched: a stream at the same rate plays
sample for sample.

>>> import numpy as np
>>> from sonibus.bus.audio import AudioChunk
>>> buffer = JitterBuffer(8000, 1, target_ms=20)
>>> buffer.push(AudioChunk.from_samples(0.0, 0, 8000, np.full(160, 0.5)))
>>> buffer.pull(200)[[0, 100, 159, 199], 0].tolist()  # faded in, 160 frames played, faded out, silence
[410, 16384, 0, 0]
>>> buffer.stats["underruns"], buffer.stats["played_frames"]
(1, 160)
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

import numpy as np
import soxr

if TYPE_CHECKING:
    from .audio import AudioChunk

__all__ = ["JitterBuffer"]

FADE_S = 0.005        # fade-in and fade-out at every edge between sound and silence
LEVEL_TAU_S = 2.0     # how slowly the buffer's level is followed (arrivals make it saw-tooth around target)
DEADBAND = (-0.25, 0.5)  # a level this far under / over target (fractions of it) is left alone: no rate change
# (wider over target: more buffered is only latency, up to max_ms; less is the way to running dry)
GAIN = 0.02           # rate change per unit of level error past the dead band
SCALE = 32768.0       # int16 ↔ float in [-1, 1): a power of two, so int16 round-trips exactly
MAX_CHANNELS = 8


class JitterBuffer:
    """Chunks in (``push``, any thread), a steady stream out (``pull``): int16 of
    ``rate`` Hz and ``channels`` channels. ``stats``: ``underruns`` (times it ran
    dry), ``overruns`` (frames dropped for being too many), ``gaps`` (chunks
    missing by ``seq``), ``refused`` (chunks it could not use: ``seq`` gone
    back), ``played_frames`` (frames played from the buffer, gaps' silence
    included)."""

    def __init__(self, rate: int, channels: int, target_ms: float = 100.0,
                 max_ms: float | None = None, ceiling: float = 1.0, follow_drift: float = 0.005) -> None:
        max_ms = 3 * target_ms if max_ms is None else max_ms
        for value, name, valid, fix in (
                (rate, "rate", isinstance(rate, int) and rate > 0, "a positive integer, in Hz"),
                (channels, "channels", isinstance(channels, int) and 1 <= channels <= MAX_CHANNELS,
                 f"an integer in 1..{MAX_CHANNELS}"),
                (target_ms, "target_ms", target_ms > 0, "a positive number of ms"),
                (max_ms, "max_ms", max_ms > target_ms, f"more than target_ms ({target_ms:g})"),
                (ceiling, "ceiling", 0 < ceiling <= 1, "a fraction of full scale in (0, 1]"),
                (follow_drift, "follow_drift", 0 <= follow_drift <= 0.05, "a fraction of the rate in [0, 0.05]")):
            if not valid:
                raise ValueError(f"jitter buffer {name} = {value!r}: expected {fix}")
        self.rate, self.channels, self.ceiling = rate, channels, ceiling
        self.target = max(1, round(rate * target_ms / 1000))              # frames
        self.limit = max(self.target + 1, round(rate * max_ms / 1000))    # frames
        self.stats: dict[str, int] = {"underruns": 0, "overruns": 0, "gaps": 0, "refused": 0, "played_frames": 0}
        fade = max(1, min(round(rate * FADE_S), self.target // 2))
        self._up = np.linspace(0.0, 1.0, fade + 1, dtype=np.float32)[1:, np.newaxis]  # 1/fade .. 1
        self._down = 1.0 - self._up                                                   # .. 0
        self._lock = threading.Lock()       # the queue (pull may run in a real-time callback: kept short)
        self._push_lock = threading.Lock()  # the sender's state and the converter (pushes in order)
        self._buffer = np.zeros((2 * self.limit + rate // 5, channels), np.float32)
        self._start = self._end = 0
        self._playing = False
        self._fade_in = 0                   # frames of the next sound faded in so far (len(_up): done)
        self._tail = np.zeros((0, channels), np.float32)  # the rest of a fade-out to play before silence
        self._last = np.zeros(channels, np.float32)  # the last frame played
        self._converter: _Converter | None = None
        self._next_seq: int | None = None
        self.follow_drift = follow_drift
        self.ratio = 1.0                    # frames taken from the buffer per frame played (drift following)
        self._level = 0.0                   # the buffer's level past target, averaged (a fraction of target)
        self._phase = 0.0                   # where between two buffered frames the next one is read
        self._last_t = 0.0

    def __repr__(self) -> str:
        state = "playing" if self._playing else "buffering"
        return (f"<JitterBuffer {self.rate} Hz × {self.channels} {state} {self.buffered}/{self.target} frames "
                f"{self.stats}>")

    @property
    def buffered(self) -> int:
        """Frames waiting to be played."""
        return self._end - self._start

    @property
    def silent(self) -> bool:
        """Whether ``pull`` would give nothing but silence until something is pushed: nothing
        buffered, not playing, no fade-out left (a player may then wait for a push rather
        than pull silence block by block)."""
        with self._lock:
            return not self._playing and self._end == self._start and not len(self._tail)

    def push(self, chunk: AudioChunk) -> None:
        """Queue ``chunk`` (of any rate and channel count), after silence for the
        chunks missing before it; drop it if its ``seq`` goes back."""
        with self._push_lock:
            missing, new_stream = 0, False
            if self._next_seq is not None and chunk.seq != self._next_seq:
                if chunk.seq < self._next_seq and chunk.t <= self._last_t:
                    with self._lock:
                        self.stats["refused"] += 1
                    return
                # (a jump past what the buffer holds is that many: the silence of more would be cut anyway)
                most = self.limit * chunk.rate // (chunk.frames * self.rate) + 1
                missing = min(max(0, chunk.seq - self._next_seq), most)
                new_stream = chunk.seq < self._next_seq  # a sender that restarted: its sound does not follow on
            self._next_seq, self._last_t = chunk.seq + 1, chunk.t
            converter = self._converter
            restart = converter is not None and (missing or new_stream
                                                 or converter.source != (chunk.rate, chunk.channels))
            held = 0  # frames the old stream's resampler still held: silence instead (cut short, they ring)
            if converter is None or restart:
                held = converter.held() if converter is not None else 0
                converter = self._converter = _Converter(chunk.rate, chunk.channels, self.rate, self.channels)
            sound = converter.convert(chunk.samples())
            with self._lock:
                if restart:
                    self._end_sound()
                    silence = held
                    if missing:
                        self.stats["gaps"] += missing
                        silence += round(missing * chunk.frames * self.rate / chunk.rate)
                    self._append(np.zeros((min(self.limit, silence), self.channels), np.float32), fade=False)
                self._append(sound)
                if self.buffered > self.limit:
                    self._cut()

    def pull(self, frames: int) -> np.ndarray:
        """The next ``frames`` frames, int16 of shape (frames, channels): what is
        buffered, silence where nothing is."""
        out = np.zeros((frames, self.channels), np.float32)
        with self._lock:
            if not self._playing and self.buffered >= self.target:
                self._playing = True
            at = self._play_tail(out, 0)  # the rest of a fade-out comes before anything else
            self._follow(frames)
            if self.ratio != 1.0 and self._playing and not at and self._interpolate(out):
                played = at = frames
            else:
                played = min(frames - at, self.buffered) if self._playing else 0
                out[at:at + played] = self._buffer[self._start:self._start + played]
                self._start += played
                at += played
            self.stats["played_frames"] += played
            if self._playing and at < frames:  # ran dry
                self.stats["underruns"] += 1
                self._playing = False
                self._phase = 0.0
                self._fade_in = 0
                if played >= len(self._down):
                    out[at - len(self._down):at] *= self._down
                else:  # too little left to fade: from the last frame down to silence instead
                    self._tail = (out[at - 1] if at else self._last) * self._down
                    self._play_tail(out, at)
            if frames:
                self._last = out[-1].copy()
        level = np.rint(out * (SCALE * self.ceiling))
        limit = np.floor(32767 * self.ceiling)
        return np.clip(level, -limit, limit, out=level).astype(np.int16)

    # -- the queue (self._lock held) ---------------------------------------------------

    def _follow(self, frames: int) -> None:
        """Set ``ratio`` from the buffer's averaged level (see the module's docstring)."""
        if not self._playing or not self.follow_drift:
            self.ratio, self._level = 1.0, 0.0
            return
        weight = min(1.0, frames / (self.rate * LEVEL_TAU_S))
        self._level += weight * ((self.buffered - self.target) / self.target - self._level)
        past = max(DEADBAND[0] - self._level, self._level - DEADBAND[1])
        if past <= 0:  # (back on whole frames: less than one frame's shift, inaudible)
            self.ratio, self._phase = 1.0, 0.0
            return
        self.ratio = 1.0 + min(self.follow_drift, GAIN * past) * (1 if self._level > 0 else -1)

    def _interpolate(self, out: np.ndarray) -> bool:
        """Fill ``out`` reading the buffer ``ratio`` frames a frame (linear
        interpolation); False, touching nothing, if too little is buffered."""
        at = self._phase + self.ratio * np.arange(len(out))
        whole = at.astype(np.int64)
        if whole[-1] + 1 >= self.buffered:
            return False
        part = (at - whole)[:, np.newaxis].astype(np.float32)
        frames = self._buffer[self._start + whole]
        out[:] = frames + (self._buffer[self._start + whole + 1] - frames) * part
        taken = self._phase + self.ratio * len(out)
        self._start += int(taken)
        self._phase = taken - int(taken)
        return True

    def _play_tail(self, out: np.ndarray, at: int) -> int:
        """Put what is left of a fade-out into ``out`` from ``at``; where it ends."""
        tail, self._tail = self._tail[:len(out) - at], self._tail[len(out) - at:]
        out[at:at + len(tail)] = tail
        return at + len(tail)

    def _append(self, sound: np.ndarray, fade: bool = True) -> None:
        if not len(sound):
            return
        if fade and self._fade_in < len(self._up):
            ramp = self._up[self._fade_in:self._fade_in + len(sound)]
            sound = sound.copy()
            sound[:len(ramp)] *= ramp
            self._fade_in += len(ramp)
        if self._end + len(sound) > len(self._buffer):
            queued = self._buffer[self._start:self._end].copy()
            size = max(len(self._buffer), 2 * (len(queued) + len(sound)))
            self._buffer = np.zeros((size, self.channels), np.float32) if size > len(self._buffer) else self._buffer
            self._buffer[:len(queued)] = queued
            self._start, self._end = 0, len(queued)
        self._buffer[self._end:self._end + len(sound)] = sound
        self._end += len(sound)

    def _end_sound(self) -> None:
        """Fade out the end of what is queued (silence follows); fade in what comes next."""
        fade = len(self._down)
        if not self.buffered and not self._playing:
            pass  # dry after an underrun: the output has faded out already (or its fade-out is under way)
        elif self.buffered >= fade:
            self._buffer[self._end - fade:self._end] *= self._down
        else:
            last = self._buffer[self._end - 1] if self.buffered else self._last
            self._append(last * self._down, fade=False)
        self._fade_in = 0

    def _cut(self) -> None:
        """Drop the oldest frames down to ``target``, crossfading the frames about to
        play into the newest kept."""
        drop = self.buffered - self.target
        fade = len(self._down)
        head = self._buffer[self._start:self._start + fade].copy()
        self._start += drop
        self._buffer[self._start:self._start + fade] *= self._up
        self._buffer[self._start:self._start + fade] += head * self._down
        self.stats["overruns"] += drop


class _Converter:
    """One sender's chunks to the buffer's rate and channels, as float in [-1, 1):
    one soxr stream while the sender's rate stays, so chunk edges leave no seams."""

    def __init__(self, rate: int, channels: int, out_rate: int, out_channels: int) -> None:
        self.source = (rate, channels)
        self.out_channels = out_channels
        self._stream = soxr.ResampleStream(rate, out_rate, out_channels, dtype="float32") if rate != out_rate else None

    def convert(self, samples: np.ndarray) -> np.ndarray:
        sound = samples.astype(np.float32) / SCALE
        if sound.shape[1] != self.out_channels:
            mixed = sound if sound.shape[1] == 1 else sound.mean(axis=1, keepdims=True)
            sound = np.repeat(mixed, self.out_channels, axis=1)
        return self._stream.resample_chunk(sound) if self._stream is not None else sound

    def held(self) -> int:
        """Frames the resampler still holds (the stream ends here: they are not played)."""
        if self._stream is None:
            return 0
        return len(self._stream.resample_chunk(np.zeros((0, self.out_channels), np.float32), last=True))
