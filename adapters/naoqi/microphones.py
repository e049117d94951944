"""The robot's microphones on ``<robot>/audio/mic``, only while anyone listens.

NAOqi hands microphone audio to a *remote module*: a service this adapter
registers on its own libqi session (``Session.registerService``), which
``ALAudioDevice`` calls back with ``processRemote(nbOfChannels,
nbOfSamplesByChannel, timeStamp, buffer)`` once told the format
(``setClientPreferences(name, rate, channels, 0)``: interleaved) and
subscribed (``subscribe(name)``). The first bus subscriber makes the worker
subscribe, the last one leaving makes it unsubscribe (a Zenoh matching
listener, as for per-joint keys), so an idle robot sends nothing; every call
is bounded (``Link``). Each subscription registers a module of a new name, so
a robot that still lists one of a dead link never mixes them up.

A buffer (about 170 ms) is cut into chunks of at most ``CHUNK_MS``, ``seq`` +1
each; ``t`` is the robot's timestamp mapped to this machine's wall clock
(``RobotClock``), or the arrival time when the robot gives none. The chunks
are published spread over the buffer's duration (``send``), as they were
heard: a steady stream, not a burst of a buffer's worth that a congested bus
(``AUDIO`` drops rather than waits) would cut into."""

from __future__ import annotations

import contextlib
import itertools
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import qi

from sonibus.bus.audio import SAMPLE, AudioChunk

from .config import NaoqiConfig
from .connection import Link, LinkDown, RemoteError

log = logging.getLogger(__name__)

AUDIO_DEVICE = "ALAudioDevice"
CHANNEL_FLAGS = {"all": 0, "left": 1, "right": 2, "front": 3, "rear": 4}  # ALSoundExtractor's channel configurations
CHUNK_MS = 20.0      # the longest chunk published (a robot's buffer is cut into these)
RETRY_S = 1.0        # a subscription that failed is tried again this often
GOODBYE_MS = 300     # unsubscribing on stop waits this long at most (a frozen robot never answers)
MAX_AHEAD_S = 0.5    # a schedule this far ahead of now (a robot whose clock runs fast) starts again


class RobotClock:
    """Maps the robot's timestamps (``[seconds, microseconds]``) to this machine's wall clock.

    The offset is the smallest (arrival − end of buffer − robot time) of the last
    ``WINDOW`` buffers, the least delayed one: network jitter does not move ``t``
    and the robot's clock may be set to anything. A jump of the robot's clock by
    more than ``JUMP_S`` starts the estimate again. A buffer starts at most ``SLEW``
    of its length before the previous one ended: ``t`` never goes back, buffers
    that follow each other stay (nearly) contiguous, and a robot whose sound clock
    runs fast against its system clock is followed back at 1 % of real time
    instead of running ahead for ever (100 ppm: 0.36 s an hour, past the gate's
    5 s in a day)."""

    WINDOW = 64
    JUMP_S = 1.0
    SLEW = 0.01

    def __init__(self) -> None:
        self._offsets: deque[float] = deque(maxlen=self.WINDOW)
        self._end = float("-inf")  # where the previous buffer ended, wall clock
        self.source = "robot"  # robot: the robot's timestamps; receive: arrival times (no usable timestamp)

    def start(self, stamp: Any, duration: float, arrived: float) -> float:
        """Wall-clock time of the first sample of a buffer of ``duration`` s stamped ``stamp``."""
        robot = seconds(stamp)
        if robot is None:
            self.source = "receive"
            start = arrived - duration
        else:
            self.source = "robot"
            offset = arrived - duration - robot
            if self._offsets and abs(offset - min(self._offsets)) > self.JUMP_S:
                self._offsets.clear()
            self._offsets.append(offset)
            start = robot + min(self._offsets)
        start = max(start, self._end - self.SLEW * duration)
        self._end = start + duration
        return start


def seconds(stamp: Any) -> float | None:
    """``[seconds, microseconds]`` (NAOqi's timestamp) or a number as seconds; None if neither.

    >>> seconds([12, 500000]), seconds(3.5), seconds("x")
    (12.5, 3.5, None)
    """
    try:
        if isinstance(stamp, list | tuple) and len(stamp) == 2:
            return float(stamp[0]) + float(stamp[1]) / 1e6
        if isinstance(stamp, int | float) and not isinstance(stamp, bool):
            return float(stamp)
    except (TypeError, ValueError):
        pass
    return None


class MicModule:
    """The remote module ``ALAudioDevice`` calls; ``processRemote`` is its only method.

    The buffer is declared raw (``qi.Buffer``): libqi then hands it over as bytes
    (a dynamic argument carrying bytes arrives in Python 3 as a ``str``)."""

    def __init__(self, received: Callable[[int, int, Any, bytes], None]) -> None:
        self._received = received

    @qi.bind(qi.Void, [qi.Int32, qi.Int32, qi.Dynamic, qi.Buffer])
    def processRemote(self, nbOfChannels: int, nbOfSamplesByChannel: int, timeStamp: Any,
                      buffer: Any) -> None:
        self._received(nbOfChannels, nbOfSamplesByChannel, timeStamp, bytes(buffer))


@dataclass(frozen=True)
class Subscription:
    """A module registered on ``session`` and subscribed to ALAudioDevice."""

    session: Any
    name: str
    service_id: int


class Microphones:
    """Subscribes the robot's microphones while ``wanted`` and ``available``; ``run(stopping)`` is its worker,
    ``close()`` unsubscribes on the way out. Chunks go to ``publish``; ``warn(kind, message)`` and
    ``count(kind)`` are the node's."""

    def __init__(self, link: Link, config: NaoqiConfig, node_name: str, publish: Callable[[AudioChunk], None],
                 warn: Callable[[str, str], None], count: Callable[[str], None]) -> None:
        self.link, self.publish, self.warn, self.count = link, publish, warn, count
        self.rate = config.mic_rate
        self.flag = CHANNEL_FLAGS[config.mic_channels]
        self.channels = 4 if config.mic_channels == "all" else 1
        self.clock = RobotClock()
        self._base = "sonibus_" + re.sub(r"\W", "_", node_name)
        self._numbers = itertools.count(1)
        self._state = threading.Condition()
        self._wanted = False                            # anyone subscribes to <robot>/audio/mic
        self._available = False                         # connected to a robot with ALAudioDevice
        self._current: Subscription | None = None
        self._stale: list[str] = []                     # modules of dead links the robot may still list
        self._calls = threading.Lock()                  # one (un)subscription at a time: worker or close
        self._seq = -1
        self._outbox: deque[tuple[float, AudioChunk]] = deque()  # (when to publish, monotonic s; chunk)
        self._next_due = 0.0
        self._out = threading.Condition()

    @property
    def subscribed(self) -> bool:
        return self._current is not None

    def wanted(self, matching: bool) -> None:
        """Someone subscribes to the mic key now, or nobody any more (a Zenoh thread: never blocks)."""
        with self._state:
            self._wanted = matching
            self._state.notify_all()

    def available(self, present: bool) -> None:
        """The link is up to a robot that has ALAudioDevice (True), or down (False)."""
        with self._state:
            self._available = present
            self._state.notify_all()

    # -- the worker -------------------------------------------------------------------

    def run(self, stopping: threading.Event) -> None:
        while not stopping.is_set():
            with self._state:
                want = self._wanted and self._available
            current = self._current
            if current is not None and (not want or current.session is not self.link.session):
                self._unsubscribe()
            elif want and current is None:
                try:
                    self._subscribe()
                except (LinkDown, RemoteError) as exc:
                    if not stopping.is_set():
                        self.warn("mic", f"microphones not subscribed: {exc}; trying again every {RETRY_S:g} s")
                    stopping.wait(RETRY_S)
                continue
            with self._state:
                if (self._wanted and self._available) == want and not stopping.is_set():
                    self._state.wait(0.2)  # (also notices a new session: the link changes without a word)

    def send(self, stopping: threading.Event) -> None:
        """The publishing worker: each chunk at its time."""
        while not stopping.is_set():
            with self._out:
                wait = self._outbox[0][0] - time.monotonic() if self._outbox else 0.2
                if wait > 0:
                    self._out.wait(min(wait, 0.2))
                    continue
                chunk = self._outbox.popleft()[1]
            self.publish(chunk)

    def close(self) -> None:
        """Unsubscribe before the link closes (at most ``GOODBYE_MS`` per call on a robot that does not answer)."""
        with self._state:
            self._wanted = False
            self._state.notify_all()
        self._unsubscribe(goodbye=True)

    def _subscribe(self) -> None:
        with self._calls:
            generation, session = self.link.current()
            for name in self._stale:  # best effort: a robot may still list the module of a link that died
                with contextlib.suppress(RemoteError):
                    self.link.call(AUDIO_DEVICE, "unsubscribe", name)
            self._stale.clear()
            name = f"{self._base}_{next(self._numbers)}"
            module = MicModule(lambda *args: self._received(name, *args))
            service_id = self.link.wait(self.link.send(generation, session.registerService, name, module),
                                        f"registerService({name})")
            subscription = Subscription(session, name, service_id)
            try:
                self.link.call(AUDIO_DEVICE, "setClientPreferences", name, self.rate, self.flag, 0)
                self.link.call(AUDIO_DEVICE, "subscribe", name)
            except (LinkDown, RemoteError):
                self._forget(subscription)
                raise
            self._current = subscription
            log.info("microphones subscribed as %s: %d Hz, %s", name, self.rate,
                     "4 channels" if self.flag == 0 else f"channel configuration {self.flag}")

    def _unsubscribe(self, goodbye: bool = False) -> None:
        with self._calls:
            subscription, self._current = self._current, None
            if subscription is None:
                return
            if subscription.session is not self.link.session or not self.link.connected:
                self._stale.append(subscription.name)  # its link died: the next one unsubscribes it
                return
            try:
                self.link.call(AUDIO_DEVICE, "unsubscribe", subscription.name,
                               timeout_ms=GOODBYE_MS if goodbye else None, interruptible=not goodbye)
            except (LinkDown, RemoteError) as exc:
                log.debug("unsubscribe %s: %s", subscription.name, exc)
                self._stale.append(subscription.name)
            self._forget(subscription)
            log.info("microphones unsubscribed (%s)", subscription.name)

    def _forget(self, subscription: Subscription) -> None:
        """Unregister the module (the robot's service directory: bounded, it may not answer)."""
        try:
            self.link.send(None, subscription.session.unregisterService, subscription.service_id).wait(GOODBYE_MS)
        except Exception as exc:  # a session closed underneath
            log.debug("unregister %s: %s", subscription.name, exc)

    # -- what the robot sends (a libqi thread) ------------------------------------------

    def _received(self, name: str, channels: int, frames: int, stamp: Any, buffer: bytes) -> None:
        arrived = time.time()
        current = self._current
        if current is None or current.name != name:  # a late buffer of an ended subscription
            return
        if not (1 <= channels <= 8 and frames >= 1 and len(buffer) == channels * frames * 2):
            self.count("mic_refused")
            self.warn("mic_format", f"microphone buffer refused: {len(buffer)} bytes for {frames} frames "
                                    f"of {channels} channels (int16 interleaved expected)")
            return
        samples = np.frombuffer(buffer, SAMPLE).reshape(frames, channels)
        first = self.clock.start(stamp, frames / self.rate, arrived)
        now = time.monotonic()
        due = max(now, self._next_due) if self._next_due - now < MAX_AHEAD_S else now
        self._next_due = due + frames / self.rate
        step = max(1, round(self.rate * CHUNK_MS / 1000.0))
        chunks = []
        for start in range(0, frames, step):
            self._seq += 1
            piece = AudioChunk(first + start / self.rate, self._seq, self.rate, channels,
                               samples[start:start + step].tobytes())
            chunks.append((due + start / self.rate, piece))
        with self._out:
            self._outbox.extend(chunks)
            self._out.notify()
