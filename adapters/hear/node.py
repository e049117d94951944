"""The ``hear`` adapter: audio on the bus in, its features out as derived values.

One worker takes the chunks of the audio keys it listens to (a robot's microphones,
``<robot>/audio/mic``; what a JACK input plays into it, ``<robot>/audio/speaker``),
mixes nothing away (every channel counts) and publishes, per chunk, as a feature
processor does:

- ``<robot>/derived/loudness/<stream>``: the RMS level in dB full scale (-100..0);
- ``<robot>/derived/centroid/<stream>``: the spectral centroid in Hz (0..centroid_max_hz);
- ``<robot>/derived/onset/<stream>``: 1 from an onset for ``onset_hold_ms``, else 0;

each described with its unit and range on ``<robot>/info/derived``, so a map takes
them as sources with nothing typed (``pepper/derived/onset/speaker``). A sender that
sends no digital silence (the jack adapter) stops sending when its input is quiet:
after ``quiet_ms`` without a chunk the stream is said silent (-100 dB, 0 Hz, onset 0)
every ``quiet_ms`` while it lasts, not held at its last loud value; so a map hears a
quiet room as a signal, and only a node that is gone as silence.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonibus.bus import codec, keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.audio import FULL_SCALE, AudioChunk, received

from .config import HearConfig
from .features import FLOOR_DB, Onsets, centroid_hz, level_db

log = logging.getLogger(__name__)

FEATURES = (("loudness", "dB"), ("centroid", "Hz"), ("onset", ""))


@dataclass
class _Stream:
    """One listened audio key: its onset detector and what it said last."""

    robot: str
    stream: str
    onsets: Onsets
    seq: int = 0
    heard: float = 0.0          # monotonic time of its last chunk (0: none yet)
    onset_until: float = 0.0    # chunk time (s) until which the onset value is 1
    quiet: bool = True          # silent since its last chunk
    said: float = 0.0           # monotonic time of its last values published
    last_t: float = 0.0         # their t: each stream's t only grows (a sink's pacing skips a t that goes back)
    duration: float = 0.0       # of its last chunk (s)
    publishers: dict[str, Any] = field(default_factory=dict)


class Hear(Adapter):
    """Loudness, spectral centroid and onsets of audio on the bus, as derived values with ranges."""

    Config = HearConfig
    counters = ("chunks", "onsets", "quiet", "received", "bad")

    def _start(self) -> None:
        cfg: HearConfig = self.config
        self._gate = messages.Gate(self.bus.limits)
        self._streams: dict[str, _Stream] = {}
        subscriber_queue = None
        for robot, stream in cfg.streams:
            state = _Stream(robot, stream, Onsets(cfg.onset_db, cfg.onset_min_db, cfg.onset_hold_ms / 1000.0))
            state.publishers = {feature: self.own(self.bus.stream_publisher(keys.derived(robot, feature, stream)))
                                for feature, _ in FEATURES}
            self._streams[keys.audio(robot, stream)] = state
            subscriber, subscriber_queue = self.bus.subscribe(keys.audio(robot, stream), maxlen=cfg.queue,
                                                              queue=subscriber_queue)
            self.own(subscriber)
        self._queue = self.own(subscriber_queue)
        for robot in dict.fromkeys(robot for robot, _ in cfg.streams):
            reply, where = codec.encode(self.described(robot)), keys.derived_info(robot)
            self.own(self.bus.serve(where, lambda query, where=where, reply=reply:
                                    query.reply(where, reply, encoding=codec.ENCODING)))
        self.address = "listening to " + ", ".join(cfg.listen)
        self.spawn(self._run, "hear")

    def described(self, robot: str) -> dict[str, Any]:
        """The ``<robot>/info/derived`` reply: each feature of each of ``robot``'s listened streams."""
        cfg: HearConfig = self.config
        spans = {"loudness": (FLOOR_DB, 0.0), "centroid": (0.0, cfg.centroid_max_hz), "onset": (0.0, 1.0)}
        return {"robot": robot, "processor": {"host": self.bus.host, "node": self.name},
                "derived": [{"name": f"{feature}/{stream}", "key": keys.derived(robot, feature, stream),
                             "unit": unit, "size": 1, "min": spans[feature][0], "max": spans[feature][1],
                             "sources": [keys.audio(robot, stream)]}
                            for r, stream in cfg.streams if r == robot for feature, unit in FEATURES]}

    def _run(self) -> None:
        quiet_s = self.config.quiet_ms / 1000.0
        while not self.stopping.is_set():
            for key, payload in self._queue.drain(timeout=min(0.02, quiet_s / 2)):
                chunk = received(self._gate, key, payload, self.count, self.warn)
                state = self._streams.get(key)
                if chunk is not None and state is not None:
                    self._hear(state, chunk)
            now = time.monotonic()
            for state in self._streams.values():
                quiet = max(quiet_s, 2 * state.duration)  # (a sender of 100 ms chunks is not silent between them)
                if now - state.heard >= quiet and now - state.said >= quiet:
                    self._silence(state, quiet)

    def _hear(self, state: _Stream, chunk: AudioChunk) -> None:
        samples = chunk.samples().astype(np.float32) / FULL_SCALE
        db = level_db(samples)
        if state.onsets(chunk.t, db):
            state.onset_until = chunk.t + self.config.onset_hold_ms / 1000.0
            self.count("onsets")
        centroid = min(centroid_hz(samples, chunk.rate), self.config.centroid_max_hz) if db > FLOOR_DB else 0.0
        state.heard, state.quiet, state.duration = time.monotonic(), False, chunk.duration
        self._publish(state, chunk.t, db, centroid, 1.0 if chunk.t < state.onset_until else 0.0)
        self.count("chunks")
        self.record_latency(time.time() - chunk.t)

    def _silence(self, state: _Stream, quiet: float) -> None:
        """No chunk for ``quiet_ms``: the stream is silent, said every ``quiet_ms`` while it lasts (a
        signal, not a gap: a map tells a quiet room from a node that is gone); an onset lasts its hold."""
        if not state.quiet:
            state.quiet = True
            state.onsets.quiet()
            self.count("quiet")
        # stamped ``quiet`` ago: the next chunk's t (its first sample's time: before it arrived) must
        # not be older than this, or the sinks' pacing would skip the clap that ends the silence
        t = time.time() - quiet
        self._publish(state, t, FLOOR_DB, 0.0, 1.0 if time.time() < state.onset_until else 0.0)

    def _publish(self, state: _Stream, t: float, db: float, centroid: float, onset: float) -> None:
        state.seq += 1
        state.said = time.monotonic()
        t = state.last_t = max(t, state.last_t + 1e-6)
        for feature, value in (("loudness", db), ("centroid", centroid), ("onset", onset)):
            state.publishers[feature].put(codec.encode({"t": t, "seq": state.seq, "v": value}))
