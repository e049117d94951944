"""What the robot plays: ``<robot>/audio/speaker`` through a jitter buffer into
``ALAudioDevice.sendRemoteBufferToOutput(nbOfFrames, buffer)`` — 16-bit stereo
interleaved at 48 kHz, at most 16384 frames a call.

The worker sleeps until a chunk comes, then sends a block of ``BLOCK_FRAMES``
(20 ms) every 20 ms on a monotonic schedule: the jitter buffer (``bus.audio``)
turns what the bus delivers into a steady stream (silence until
``speaker_latency_ms`` is buffered and on underrun, the oldest dropped on
overrun, silence for lost chunks, other rates and channel counts converted,
never above ``volume_ceiling``). Blocks it is late for go out together in the
next call; behind by more than ``MAX_BEHIND_BLOCKS`` it starts the schedule
again. Once no chunk has come for ``idle_s`` it stops calling the robot.
A call that fails or times out is one warning and a count: the node goes on."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from sonibus.bus import keys, messages
from sonibus.bus.audio import received
from sonibus.bus.jitter import JitterBuffer
from sonibus.bus.owner import RobotAdapter

from .config import NaoqiConfig
from .connection import Link, LinkDown, RemoteError
from .microphones import AUDIO_DEVICE

OUTPUT_RATE, OUTPUT_CHANNELS = 48000, 2   # what sendRemoteBufferToOutput plays
MAX_FRAMES = 16384                       # per call, as NAOqi documents it
BLOCK_FRAMES = 960                       # 20 ms at 48 kHz
BLOCK_S = BLOCK_FRAMES / OUTPUT_RATE
MAX_BEHIND_BLOCKS = 10                   # 200 ms late: start the schedule again rather than catch up
CALL_TIMEOUT_MS = 1000                   # a call that takes longer has failed (the stream cannot wait)
COUNTERS = ("speaker_frames", "speaker_calls", "speaker_errors", "speaker_underruns", "speaker_overruns",
            "speaker_gaps", "speaker_refused")

assert MAX_BEHIND_BLOCKS * BLOCK_FRAMES <= MAX_FRAMES  # a catch-up is still one call


class Speaker:
    """Plays ``<robot>/audio/speaker`` on the robot behind ``link``; ``run()`` is the worker of ``node``."""

    def __init__(self, node: RobotAdapter, link: Link, robot: str, config: NaoqiConfig) -> None:
        self.node, self.link = node, link
        self.buffer = JitterBuffer(OUTPUT_RATE, OUTPUT_CHANNELS, target_ms=config.speaker_latency_ms,
                                   ceiling=config.volume_ceiling)
        self.idle_s = 3 * config.speaker_latency_ms / 1000.0 + 0.5  # (the buffer holds at most 3 × its target)
        subscriber, self._queue = node.bus.subscribe(keys.audio(robot, "speaker"), maxlen=256)
        node.own(subscriber)
        node.own(self._queue)
        self._gate = messages.Gate(node.bus.limits)
        self.available = threading.Event()  # connected to a robot that has ALAudioDevice
        self.largest_call = 0                # frames of the largest call sent
        for counter in COUNTERS[3:]:  # the jitter buffer's own counts
            node.stats.follow(counter, self._stat(counter.removeprefix("speaker_")))

    def _stat(self, name: str) -> Callable[[], int]:
        return lambda: self.buffer.stats[name]

    def run(self) -> None:
        stopping = self.node.stopping
        while not stopping.is_set():
            item = self._queue.get(timeout=0.5)
            if item is not None:
                self._take(*item)
                self._play(stopping)

    def _play(self, stopping: threading.Event) -> None:
        """Send a block every ``BLOCK_S`` until no chunk has come for ``idle_s``."""
        start = last_input = time.monotonic()
        sent = 0  # blocks since start
        while not stopping.is_set():
            items = self._queue.drain(0)
            for item in items:
                self._take(*item)
            now = time.monotonic()
            if items:
                last_input = now
            elif now - last_input > self.idle_s:
                return
            due = max(1, int((now - start) / BLOCK_S) + 1 - sent)  # (float rounding must not make it 0)
            if due > MAX_BEHIND_BLOCKS:  # a stall: what piled up is the jitter buffer's overrun to drop
                start, sent, due = now, 0, 1
            self._send(self.buffer.pull(due * BLOCK_FRAMES))
            sent += due
            stopping.wait(max(0.0, start + sent * BLOCK_S - time.monotonic()))

    def _take(self, key: str, payload: bytes) -> None:
        chunk = received(self._gate, key, payload, self.node.count, self.node.warn)
        if chunk is not None:
            self.buffer.push(chunk)

    def _send(self, block: np.ndarray) -> None:
        frames = len(block)
        assert 1 <= frames <= MAX_FRAMES, f"{frames} frames in one call"
        if not self.available.is_set() or not self.node.ownership.active:
            return  # no robot, one without ALAudioDevice, or another node owns it: played to nobody
        self.largest_call = max(self.largest_call, frames)
        try:
            played: Any = self.link.call(AUDIO_DEVICE, "sendRemoteBufferToOutput", frames, block.tobytes(),
                                         timeout_ms=CALL_TIMEOUT_MS)
        except (LinkDown, RemoteError) as exc:
            self._failed(str(exc))
            return
        if played is False:  # NAOqi's "False otherwise"
            self._failed(f"{AUDIO_DEVICE}.sendRemoteBufferToOutput answered False for {frames} frames")
            return
        self.node.count("speaker_calls")
        self.node.count("speaker_frames", frames)

    def _failed(self, reason: str) -> None:
        if self.node.stopping.is_set():  # (the call in flight was cut short by the stop)
            return
        self.node.count("speaker_errors")
        self.node.warn("speaker", f"the robot did not play a block: {reason}")
