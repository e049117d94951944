"""The sim robot's audio: microphones that hear its motors, a speaker that plays in real time.

``SimMic`` publishes the body's servo whine (``whine.py``) on ``<robot>/audio/mic``
in chunks, only while anyone subscribes there (nothing is rendered otherwise, and it
waits for a listener rather than waking every 20 ms).
``SimSpeaker`` takes ``<robot>/audio/speaker`` into a jitter buffer and drains it
at the speaker's rate, as a sound card would, keeping the last seconds it played;
while it has nothing to play it waits for a chunk (up to ``IDLE_S``) instead of
pulling silence every 20 ms, and counts the silence it played when it wakes.
Both run on monotonic deadlines (``bus/pacing.py``): a stall skips, never bursts.
"""

from __future__ import annotations

import functools
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from sonibus.bus import codec, keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.audio import AudioChunk, received
from sonibus.bus.jitter import JitterBuffer
from sonibus.bus.node import AUDIO
from sonibus.bus.owner import RobotAdapter
from sonibus.bus.pacing import Pacer
from sonibus.bus.robot import RobotModel

from .nap import Nap
from .whine import Whine

MIC_COUNTERS = ("mic_chunks",)
IDLE_S = 1.0  # a silent speaker, an unheard mic, wake this often at most (20 ms ticks: ~1 % of a core for nothing;
             # 0.2 s: 0.3 % for the speaker alone, issue 35); sound, a listener or a stop wakes them at once
SPEAKER_COUNTERS = ("speaker_frames", "speaker_underruns", "speaker_overruns", "speaker_gaps", "speaker_refused")


@dataclass(frozen=True)
class Format:
    """A stream's sample rate (Hz), channel count and chunk length (ms)."""

    rate: int
    channels: int
    chunk_ms: float = 20.0

    @property
    def frames(self) -> int:
        return round(self.rate * self.chunk_ms / 1000.0)

    def info(self) -> dict[str, int]:
        return {"rate": self.rate, "channels": self.channels}


MIC = Format(16000, 1)
SPEAKER = Format(48000, 2)


class SimMic:
    """Publishes ``Whine(speeds())`` on ``<robot>/audio/mic`` while anyone listens; ``run()`` is
    the node's worker (until it stops). A chunk's ``t`` is its first sample's place on the schedule."""

    def __init__(self, node: RobotAdapter, robot: str, model: RobotModel, speeds: Callable[[], Mapping[str, float]],
                 fmt: Format = MIC) -> None:
        self.node, self.fmt, self.speeds = node, fmt, speeds
        self.whine = Whine(fmt.rate, fmt.channels, model=model)
        key = keys.audio(robot, "mic")
        self._publisher = node.own(node.bus.stream_publisher(key, AUDIO))
        self.listening = False
        self._listened = threading.Event()  # set while anyone listens (or the node stops): a silent mic waits on it
        node.own(node.bus.watch_subscribers(key, self._wanted))
        self._seq = -1
        self._last: int | None = None  # the frame of the last chunk sent, while listening
        self.pacer = Pacer(1000.0 / fmt.chunk_ms)  # (its skipped ticks: mostly waits for a listener)

    def _wanted(self, matching: bool) -> None:
        self.listening = matching
        if matching:
            self._listened.set()
        else:
            self._listened.clear()

    def close(self) -> None:
        """Wake ``run`` from its wait for a listener (the node is stopping)."""
        self._listened.set()

    def run(self) -> None:
        period = self.fmt.chunk_ms / 1000.0
        wall0 = time.time()

        def tick(frame: int) -> None:
            if not self.listening or not self.node.ownership.active:  # (standing by: the owner's mic speaks)
                self._last = None
                if not self.listening:  # nobody listens: wait for one (up to IDLE_S), not a wake-up per chunk
                    self._listened.wait(IDLE_S)
                return
            # frames the pacer skipped while listening show as a gap in seq
            self._seq += 1 if self._last is None else frame - self._last
            self._last = frame
            samples = self.whine.render(self.fmt.frames, self.speeds())
            chunk = AudioChunk.from_samples(wall0 + (frame - 1) * period, self._seq, self.fmt.rate, samples)
            self._publisher.put(codec.encode(chunk.message()))
            self.node.count("mic_chunks")

        self.pacer.run(tick, Nap(self.node.stopping))  # type: ignore[arg-type]  # (an Event to the pacer)


class SimSpeaker:
    """Plays ``<robot>/audio/speaker`` through a jitter buffer in real time; run ``run()``.

    ``played`` holds the last ``keep_s`` seconds or so it played (int16 blocks of 20 ms, longer after a
    stall or a silence): kept by their length, not their count (500 blocks of a second's silence are 96 MB)."""

    def __init__(self, node: Adapter, robot: str, target_ms: float, fmt: Format = SPEAKER,
                 keep_s: float = 10.0) -> None:
        self.node, self.fmt = node, fmt
        self.buffer = JitterBuffer(fmt.rate, fmt.channels, target_ms=target_ms)
        subscriber, self._queue = node.bus.subscribe(keys.audio(robot, "speaker"), maxlen=256)
        node.own(subscriber)
        node.own(self._queue)
        self._gate = messages.Gate(node.bus.limits)
        self.played: deque[np.ndarray] = deque()
        self._kept, self._keep = 0, max(fmt.frames, round(keep_s * fmt.rate))  # frames in played, at most
        for counter in SPEAKER_COUNTERS[1:]:  # the jitter buffer's own counts
            node.stats.follow(counter, functools.partial(self._buffer_stat, counter.removeprefix("speaker_")))

    def run(self) -> None:
        last = -1

        def tick(frame: int) -> None:
            nonlocal last
            # silent: wait for a chunk (or IDLE_S); the pacer then skips the ticks slept through, and
            # the next tick plays their silence at once, as a stalled card would
            for key, payload in self._queue.drain(IDLE_S if self.buffer.silent and frame == last + 1 else 0):
                self._take(key, payload)
            frames = self.fmt.frames * (frame - last)  # a stalled card still plays what the skipped ticks would
            last = frame
            # silence that nothing changes (nothing queued or playing, no fade left; only this thread
            # pushes): zeros, not pulled — a second of it pulled made and scaled 1 MB of floats
            # after each wait (issue 35)
            silent = self.buffer.silent
            self._play(np.zeros((frames, self.fmt.channels), np.int16) if silent else self.buffer.pull(frames))
            self.node.count("speaker_frames", frames)

        Pacer(1000.0 / self.fmt.chunk_ms).run(tick, Nap(self.node.stopping))  # type: ignore[arg-type]

    def _play(self, block: np.ndarray) -> None:
        """Keep ``block`` in ``played``, and of the blocks before it what ``keep_s`` holds."""
        self.played.append(block)
        self._kept += len(block)
        while self._kept - len(self.played[0]) >= self._keep:
            self._kept -= len(self.played.popleft())

    def close(self) -> None:
        """Wake ``run`` from its wait on the queue (the node is stopping)."""
        self._queue.close()

    def _buffer_stat(self, name: str) -> int:
        return self.buffer.stats[name]

    def _take(self, key: str, payload: bytes) -> None:
        chunk = received(self._gate, key, payload, self.node.count, self.node.warn)
        if chunk is not None:
            self.buffer.push(chunk)


def info(mic: bool, speaker: bool) -> dict[str, Any]:
    """The ``audio`` field of the robot's info."""
    return {"mic": MIC.info() if mic else None, "speaker": SPEAKER.info() if speaker else None}
