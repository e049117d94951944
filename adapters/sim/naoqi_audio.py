"""The fake robot's ``ALAudioDevice``: microphones that hear its motors, a
speaker that keeps what it was given to play — with NAOqi's limits.

Microphones: a client registers a module (a service of its own), sets its
format (``setClientPreferences(name, 16000 | 48000, channels flag, 0)``:
0 = all four microphones, 1-4 = left, right, front, rear alone) and
``subscribe(name)``s; every ``mic_buffer`` frames at 48 kHz (8192: 170 ms, as
ALAudioDevice's ``inputBufferSize``) the device calls the module's
``processRemote(nbOfChannels, nbOfSamplesByChannel, [seconds, microseconds],
buffer)`` with the body's servo whine (``whine.py``) at the joints' speeds now,
int16 interleaved, stamped with the fake robot's clock (wall clock +
``clock_offset_s``) at the buffer's first sample. A call still in flight when
the next buffer is due makes that buffer skipped; a module that is gone is
dropped.

Speaker: ``sendRemoteBufferToOutput(nbOfFrames, buffer)`` takes 16-bit stereo
interleaved frames (48 kHz), refuses more than 16384 frames or a buffer whose
size is not ``nbOfFrames`` × 4 bytes, and keeps the last ``played_max_s``
seconds (``played()``; ``dumpPlayed(path)`` writes them as a WAV)."""

from __future__ import annotations

import logging
import threading
import time
import wave
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import qi

from sonibus.bus.pacing import Pacer

from .naoqi_services import _Service, delayed
from .whine import Whine

log = logging.getLogger(__name__)

CHANNELS = {0: 4, 1: 1, 2: 1, 3: 1, 4: 1}  # channel configuration flag → channels delivered
RATES = (16000, 48000)
OUTPUT_RATE, OUTPUT_CHANNELS = 48000, 2
MAX_OUTPUT_FRAMES = 16384
DEFAULT_FORMAT = (48000, 0)  # what a module that never set its preferences gets


@dataclass
class Listener:
    """A subscribed module: its proxy, its format and its own whine."""

    name: str
    proxy: Any
    rate: int
    channels: int
    whine: Whine
    pending: Any = None  # the processRemote call in flight


@qi.multiThreaded()
class ALAudioDevice(_Service):
    def __init__(self, fake: Any) -> None:
        super().__init__(fake)
        self.preferences: dict[str, tuple[int, int]] = {}
        self.listeners: dict[str, Listener] = {}
        self.calls = 0            # sendRemoteBufferToOutput calls, refused ones included
        self.refused = 0
        self.largest = 0          # frames of the largest call played
        self.delivered = 0        # processRemote calls made
        self.skipped = 0          # buffers not sent: the module's previous call was still in flight
        self._played: deque[np.ndarray] = deque()
        self._played_frames = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- microphones ----------------------------------------------------------------

    @delayed
    def setClientPreferences(self, name: str, rate: int, channels: int, deinterleaved: int) -> None:
        if rate not in RATES:
            raise RuntimeError(f"ALAudioDevice::setClientPreferences: sample rate {rate} is not supported "
                               f"(16000 or 48000)")
        if channels not in CHANNELS:
            raise RuntimeError(f"ALAudioDevice::setClientPreferences: unknown channel configuration {channels}")
        if deinterleaved:
            raise RuntimeError("ALAudioDevice::setClientPreferences: this fake sends interleaved buffers only")
        with self._lock:
            self.preferences[name] = (int(rate), int(channels))

    @delayed
    def subscribe(self, name: str) -> None:
        rate, flag = self.preferences.get(name, DEFAULT_FORMAT)
        try:
            proxy = self.fake.session.service(name)
        except RuntimeError:
            raise RuntimeError(f"ALAudioDevice::subscribe: no module named {name}") from None
        with self._lock:
            if name in self.listeners:
                raise RuntimeError(f"ALAudioDevice::subscribe: module {name} is already subscribed")
            self.listeners[name] = Listener(name, proxy, rate, CHANNELS[flag],
                                            Whine(rate, CHANNELS[flag], model=self.engine.model))

    @delayed
    def unsubscribe(self, name: str) -> None:
        with self._lock:
            if self.listeners.pop(name, None) is None:
                raise RuntimeError(f"ALAudioDevice::unsubscribe: module {name} is not subscribed")

    @qi.nobind
    def start(self) -> None:
        """Deliver microphone buffers until ``stop()``."""
        self._thread = threading.Thread(target=self._deliver, name="fake-naoqi-mic", daemon=True)
        self._thread.start()

    @qi.nobind
    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _deliver(self) -> None:
        frames_48k = self.fake.config.mic_buffer
        period = frames_48k / OUTPUT_RATE

        def tick(_: int) -> None:
            if not self.fake.wait_answering():
                return
            stamp = time.time() + self.fake.config.clock_offset_s - period  # the buffer's first sample
            speeds = self.engine.speeds()
            with self._lock:
                listeners = list(self.listeners.values())
            for listener in listeners:
                self._send(listener, frames_48k * listener.rate // OUTPUT_RATE, stamp, speeds)

        Pacer(1.0 / period).run(tick, self._stop)

    def _send(self, listener: Listener, frames: int, stamp: float, speeds: dict[str, float]) -> None:
        pending = listener.pending
        if pending is not None and not pending.isFinished():
            self.skipped += 1
            return
        if pending is not None and pending.hasError():  # the module is gone (its client went away)
            log.info("fake ALAudioDevice: dropping module %s: %s", listener.name, pending.error().splitlines()[0])
            with self._lock:
                self.listeners.pop(listener.name, None)
            return
        pcm = listener.whine.render(frames, speeds).tobytes()
        seconds = int(stamp)
        listener.pending = listener.proxy.processRemote(listener.channels, frames,
                                                        [seconds, int((stamp - seconds) * 1e6)], pcm, _async=True)
        self.delivered += 1

    # -- speaker --------------------------------------------------------------------

    @delayed
    @qi.bind(qi.Bool, [qi.Int32, qi.Buffer])
    def sendRemoteBufferToOutput(self, nbOfFrames: int, buffer: Any) -> bool:
        data = bytes(buffer)
        with self._lock:
            self.calls += 1
            if not 1 <= nbOfFrames <= MAX_OUTPUT_FRAMES:
                self.refused += 1
                raise RuntimeError(f"ALAudioDevice::sendRemoteBufferToOutput: nbOfFrames {nbOfFrames} is not "
                                   f"in [1, {MAX_OUTPUT_FRAMES}]")
            if len(data) != nbOfFrames * 2 * OUTPUT_CHANNELS:
                self.refused += 1
                raise RuntimeError(f"ALAudioDevice::sendRemoteBufferToOutput: a buffer of {len(data)} bytes is not "
                                   f"{nbOfFrames} frames of 16-bit stereo ({nbOfFrames * 2 * OUTPUT_CHANNELS} bytes)")
            self.largest = max(self.largest, nbOfFrames)
            self._played.append(np.frombuffer(data, "<i2").reshape(nbOfFrames, OUTPUT_CHANNELS))
            self._played_frames += nbOfFrames
            keep = round(self.fake.config.played_max_s * OUTPUT_RATE)
            while self._played_frames - len(self._played[0]) >= keep:
                self._played_frames -= len(self._played.popleft())
        return True

    @qi.nobind
    def played(self) -> np.ndarray:
        """What it played (the last ``played_max_s`` seconds at most): int16, ``(frames, 2)`` at 48 kHz."""
        with self._lock:
            blocks = list(self._played)
        return np.concatenate(blocks) if blocks else np.zeros((0, OUTPUT_CHANNELS), np.int16)

    @delayed
    def dumpPlayed(self, path: str) -> int:
        """Write what it played to ``path`` (WAV, 48 kHz, 16-bit stereo); the frames written."""
        return self.dump(path)

    @qi.nobind
    def dump(self, path: str) -> int:
        """``dumpPlayed``, called in this process (by the fake's stop, when no call is taken any more)."""
        samples = self.played()
        with wave.open(str(path), "wb") as out:
            out.setnchannels(OUTPUT_CHANNELS)
            out.setsampwidth(2)
            out.setframerate(OUTPUT_RATE)
            out.writeframes(samples.astype("<i2").tobytes())
        return len(samples)
