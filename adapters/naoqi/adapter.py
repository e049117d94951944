"""The ``naoqi`` robot adapter: a real Pepper or NAO over libqi.

``start()`` returns at once; the acquisition thread connects (retrying with
backoff, one log line per outage), learns the robot (``discover``), then reads
every joint once per frame until the link breaks or the node stops, and
connects again. Its connection state (``bus/connection.py``) goes from
``connecting`` to ``connected``, ``not_answering`` (no frame read for
``answer_timeout_s``) and ``lost``; a ``status`` event every
``status_every_s`` gives the achieved rate and read latency.
With ``audio`` (and a robot that has ALAudioDevice) its microphones go to
``<robot>/audio/mic`` while anyone listens (``microphones``) and
``<robot>/audio/speaker`` is played on it (``speaker``)."""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Sequence
from typing import Any

from sonibus.bus import codec, keys
from sonibus.bus.audio import AudioChunk
from sonibus.bus.errors import CommandError
from sonibus.bus.node import AUDIO
from sonibus.bus.owner import RobotAdapter
from sonibus.bus.pacing import Pacer
from sonibus.bus.robot import load_model

from .acquire import Reader, ReadTimes
from .commands import NaoqiCommands
from .config import NaoqiConfig
from .connection import Link, LinkDown, RemoteError
from .discover import Robot, discover
from .events import RobotEvents
from .microphones import AUDIO_DEVICE, Microphones
from .speaker import COUNTERS as SPEAKER_COUNTERS
from .speaker import OUTPUT_CHANNELS, OUTPUT_RATE, Speaker

log = logging.getLogger(__name__)
announce = logging.getLogger(f"{__name__}.connected")  # "connected to Pepper 'x' at ...": said at the default level
announce.setLevel(logging.INFO)

BACKOFF_START_S = 0.25
CONNECT_ERRORS = (LinkDown, RemoteError, ValueError, TypeError)  # TypeError/ValueError: an odd answer


class NaoqiRobot(RobotAdapter):
    """A Pepper or NAO over NAOqi: joints, behaviors, speech, postures."""

    Config = NaoqiConfig
    Verbs = NaoqiCommands
    verbs: NaoqiCommands
    counters = ("mic_chunks", "mic_refused", *SPEAKER_COUNTERS)
    first_state = "connecting"  # (the acquisition thread dials the robot once the node runs)

    def _open(self) -> None:
        self.model = load_model(self.config.model_name)  # until the robot tells its own
        self.rate_hz = self.config.rate_hz
        self.read_times = ReadTimes()
        self.events = RobotEvents(self.publish_event)
        self.link = Link(self.config, self._lost, self.stopping)
        # (three frames at least: a robot read once a second is not silent between its frames)
        self.connection.answer_s = max(self.config.answer_timeout_s, 3.0 / self.config.rate_hz)
        self.connection.details = {"url": self.link.url}  # (in the first event, "connecting", too)
        self.verbs = NaoqiCommands(self.link, self.events, lambda: self.model, self._down,
                                   lambda: self.connection.state == "connected",
                                   lambda since: self.connection.answered_since(since, self.stopping))
        self.facts: Robot | None = None
        self.frames_skipped = 0
        self._pacer: Pacer | None = None  # the streaming run going on
        self._halt = threading.Event()       # ends the current streaming run
        self._error = "not connected yet"
        self._seq, self._lost_at = -1, 0.0
        self.audio_present = False  # the robot connected now has ALAudioDevice
        self.microphones: Microphones | None = None
        self.speaker: Speaker | None = None
        if self.config.audio:
            self._open_audio()

    def _open_audio(self) -> None:
        key = keys.audio(self.robot, "mic")
        self._mic = self.own(self.bus.stream_publisher(key, AUDIO))
        microphones = self.microphones = Microphones(self.link, self.config, self.name, self._publish_mic,
                                                     self.warn, self.count)
        self.own(self.bus.watch_subscribers(key, microphones.wanted))
        self.speaker = Speaker(self, self.link, self.robot, self.config)
        self.spawn(lambda: microphones.run(self.stopping), "microphones")
        self.spawn(lambda: microphones.send(self.stopping), "mic-out")
        self.spawn(self.speaker.run, "speaker")

    def _stop(self) -> None:
        if not hasattr(self, "link"):  # start failed before _open finished
            return
        self._halt.set()
        if self.microphones is not None:
            self.microphones.close()
        self._audio(False)
        try:
            self.verbs.restore_awareness()
        except (LinkDown, RemoteError) as exc:
            log.warning("%s: could not restore basic awareness: %s", self.name, exc)
        self.link.close()

    # -- connecting -------------------------------------------------------------------

    def _acquire(self) -> None:
        delay, failures = BACKOFF_START_S, 0
        while not self.stopping.is_set():
            try:
                reader = self._connect()
            except Exception as exc:  # whatever the robot answers, the node stays up and retries
                if self.stopping.is_set():
                    break
                if not isinstance(exc, CONNECT_ERRORS):
                    log.exception("%s: unexpected error while connecting to %s", self.name, self.link.url)
                self._error = str(exc)
                failures += 1
                if failures == 1:  # one line per outage
                    log.warning("%s: robot '%s' is unreachable at %s (%s); retrying, backoff up to %g s",
                                self.name, self.robot, self.link.url, exc, self.config.retry_max_s)
                    self._announce("lost")
                log.debug("%s: connect to %s failed: %s", self.name, self.link.url, exc)
                self.stopping.wait(delay)
                delay = min(delay * 2, self.config.retry_max_s)
                continue
            delay, failures = BACKOFF_START_S, 0
            self._stream(reader)
            if not self.stopping.is_set():
                failures = 1  # this line reports the outage
                log.warning("%s: lost robot '%s' at %s (%s); reconnecting", self.name, self.robot,
                            self.link.url, self._error)
                self._lost_at = time.monotonic()
                self._announce("lost")

    def _connect(self) -> Reader:
        self._halt.clear()
        self.link.connect()
        robot = discover(self.link, self.config)
        polled = self.events.attach(self.link)
        reader = self._reader(robot, polled)
        robot = dataclasses.replace(robot, source=reader.source)
        self.verbs.connected(robot.behaviors)
        self.verbs.send_pending_stop()
        if self.microphones is not None:
            self._audio(self._has_audio())
        if self.config.pause_awareness:
            try:
                self.verbs.pause_awareness()
            except RemoteError as exc:
                log.warning("%s: could not pause basic awareness: %s", self.name, exc)
        self.verbs.aware.read()
        self.model, self.facts, self._error = robot.model, robot, ""
        for difference in robot.differences:
            log.info("%s: limits from the robot differ: %s", self.name, difference)
        announce.info("%s: connected to %s at %s (NAOqi %s): %d joints from %s, speech events by %s%s",
                      self.name, robot.title, self.link.url, robot.version or "version unknown", len(reader.names),
                      reader.source, self.events.mode,
                      "" if reader.polling or not reader.polled else " (its keys are not raised yet)")
        self._announce("connected")
        return reader

    def _reader(self, robot: Robot, polled: Sequence[str]) -> Reader:
        """A reader that works here: without extras, then from ALMotion, if it must. Polled event
        keys never decide it (one that does not exist yet is read once it does)."""
        names, extra = robot.model.joint_names, self.config.extra
        tries = [(robot.source, extra), (robot.source, ()), ("motion", ())]
        error: Exception | None = None
        for source, quantities in dict.fromkeys(tries):
            reader = Reader(self.link, names, source, quantities, polled)
            try:
                reader.read()
            except (RemoteError, ValueError, TypeError) as exc:
                log.warning("%s: reading joints from %s with %s failed: %s", self.name, source,
                            ", ".join(quantities) or "positions only", exc)
                error = exc
                continue
            return reader
        raise RemoteError(f"no way to read the joints worked: {error}")

    def _lost(self, reason: str) -> None:
        self._error = reason
        self._halt.set()
        self._audio(False)

    # -- audio ------------------------------------------------------------------------

    def _has_audio(self) -> bool:
        try:
            self.link.service(AUDIO_DEVICE)
        except RemoteError as exc:
            log.info("%s: robot '%s' has no audio: %s", self.name, self.robot, exc)
            return False
        return True

    def _audio(self, present: bool) -> None:
        """Audio works now (connected to a robot with ALAudioDevice), or not."""
        self.audio_present = present and self.microphones is not None
        if self.microphones is not None and self.speaker is not None:
            self.microphones.available(self.audio_present)
            if self.audio_present:
                self.speaker.available.set()
            else:
                self.speaker.available.clear()

    def _publish_mic(self, chunk: AudioChunk) -> None:
        if self.ownership.active:  # (standing by: the owner's microphones speak)
            self._mic.put(codec.encode(chunk.message()))
            self.count("mic_chunks")

    def _announce(self, state: str) -> None:
        self.connection.set(state, self._error if state == "lost" else "", url=self.link.url)

    def _down(self, what: str) -> CommandError:
        return CommandError("not_connected", f"{what}: robot '{self.robot}' is not connected (last error: "
                                             f"{self._error}) — {self.connection_hint()}")

    def connection_hint(self) -> str:
        return f"its owner retries; check the robot is on and reachable at {self.link.url}"

    @property
    def stop_pending(self) -> bool:  # type: ignore[override]  # (the verbs keep it)
        return self.verbs.stop_pending

    # -- streaming --------------------------------------------------------------------

    def _stream(self, reader: Reader) -> None:
        gap = int((time.monotonic() - self._lost_at) * self.rate_hz) if self._lost_at else 0
        base = self._seq + 1 + gap  # seq goes on across reconnects; the outage shows as a gap
        pacer = self._pacer = Pacer(self.rate_hz)
        self.read_times.clear()
        next_status = time.monotonic() + self.config.status_every_s

        def tick(frame: int) -> None:
            nonlocal next_status
            try:
                read = reader.read()
            except Exception as exc:
                if not isinstance(exc, CONNECT_ERRORS):
                    log.exception("%s: unexpected error reading joints", self.name)
                self.link.lost(f"reading joints: {exc}")
                self._halt.set()
                return
            self._seq = base + frame
            self.publish_frame(read.t, self._seq, read.positions, reader.names, read.extra)
            if read.polled:
                self.events.poll(read.polled)
            self.read_times.add(read.read_s)
            if time.monotonic() >= next_status:
                next_status += self.config.status_every_s
                self.publish_event("status", **self.status(pacer.skipped))
                self.verbs.aware.follow()

        pacer.run(tick, self._halt)
        self.frames_skipped += pacer.skipped
        self._pacer = None

    def metrics(self) -> dict[str, Any]:
        if not hasattr(self, "read_times"):
            return {}
        pacer = self._pacer  # (the run going on: its skips are not added up yet)
        return self.status(pacer.skipped if pacer is not None else 0)

    def status(self, skipped: int = 0) -> dict[str, Any]:
        """Achieved rate, read latency, frames skipped."""
        return {**self.read_times.summary(), "frames_skipped": self.frames_skipped + skipped,
                "source": self.facts.source if self.facts else self.config.source}

    # -- what the bus sees --------------------------------------------------------------

    def behaviors(self) -> Sequence[str]:
        return self.verbs.installed

    def awareness_state(self) -> bool | None:
        return self.verbs.aware.value

    def robot_info(self) -> dict[str, Any]:
        info = super().robot_info()
        info["naoqi"] = {"url": self.link.url, "connected": self.link.connected, "error": self._error,
                         "speech_events": self.events.mode, **(self.facts.info() if self.facts else {}),
                         **self.status()}
        if self.audio_present and self.microphones is not None:
            info["audio"] = {"mic": {"rate": self.microphones.rate, "channels": self.microphones.channels},
                             "speaker": {"rate": OUTPUT_RATE, "channels": OUTPUT_CHANNELS}}
            info["naoqi"].update(mic_subscribed=self.microphones.subscribed, mic_clock=self.microphones.clock.source)
        return info

    def execute(self, verb: str, args: Any) -> dict[str, Any]:
        try:
            return super().execute(verb, args)
        except CommandError as exc:
            if exc.code == "unknown_behavior" and self.facts is None:  # no list yet to know it by
                raise self._down(verb) from None
            raise
