"""The simulated robot adapter: a Pepper or NAO that needs no robot."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from sonibus.bus.options import bad
from sonibus.bus.owner import RobotAdapter
from sonibus.bus.pacing import Pacer
from sonibus.bus.robot import load_model, models

from . import audio
from .engine import SimEngine
from .nap import Nap


@dataclass(frozen=True)
class SimConfig:
    """Options of the ``sim`` adapter."""

    robot: str = "pepper"           # bus name of the robot
    model: str = ""                 # pepper | nao; default: the robot name without digits
    rate_hz: float = 100.0
    posture: str = "StandInit"      # where the robot starts
    idle: bool = False              # gentle breathing and looking around when nothing runs
    autoplay_s: float = 0.0         # run a random behavior every N seconds (0: never)
    words_per_minute: float = 150.0  # speaking rate at say speed 100
    body_sound: bool = True         # microphones hearing the motors' whine on <robot>/audio/mic
    speaker: bool = True            # a speaker playing <robot>/audio/speaker
    speaker_latency_ms: float = 100.0  # the speaker's jitter buffer

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz <= 1000:
            raise bad("rate_hz", f"{self.rate_hz:g} must be in (0, 1000]")
        if not 10 <= self.speaker_latency_ms <= 2000:
            raise bad("speaker_latency_ms", f"{self.speaker_latency_ms:g} must be in 10..2000 ms")
        if self.model_name not in models():
            raise bad("model", f"'{self.model_name}' is unknown — known models: {', '.join(models())}")
        postures = load_model(self.model_name).postures
        if self.posture not in postures:
            raise bad("posture", f"'{self.posture}' is unknown for {self.model_name} — "
                      f"known postures: {', '.join(postures)}")

    @property
    def model_name(self) -> str:
        return self.model or self.robot.rstrip("0123456789")

    def engine(self, emit: Any) -> SimEngine:
        return SimEngine(load_model(self.model_name), emit, posture=self.posture, idle=self.idle,
                         autoplay_s=self.autoplay_s, words_per_minute=self.words_per_minute)


class SimRobot(RobotAdapter):
    """Simulated Pepper or NAO: joints, behaviors, speech, postures and body sound, no robot needed.

    Its microphones hear its motors (``audio.SimMic``) and its speaker plays ``<robot>/audio/speaker``."""

    Config = SimConfig
    counters = audio.MIC_COUNTERS + audio.SPEAKER_COUNTERS
    Verbs = SimEngine  # the engine carries out the commands
    verbs: SimEngine

    def _open(self) -> None:
        self.engine = self.config.engine(lambda kind, fields: self.publish_event(kind, **fields))
        self.verbs = self.engine
        self.model = self.engine.model
        self.rate_hz = self.config.rate_hz
        self.body = self.engine.body

    def _start(self) -> None:
        super()._start()
        if self.config.body_sound:
            self.mic = audio.SimMic(self, self.robot, self.model, self.engine.speeds)
            self.spawn(self.mic.run, "mic")
        if self.config.speaker:
            self.speaker = audio.SimSpeaker(self, self.robot, self.config.speaker_latency_ms)
            self.spawn(self.speaker.run, "speaker")

    def _stop(self) -> None:
        super()._stop()
        for audio_part in (getattr(self, "mic", None), getattr(self, "speaker", None)):
            if audio_part is not None:
                audio_part.close()  # (a silent speaker, an unheard mic, wait: now, not at their next wake-up)

    def behaviors(self) -> Sequence[str]:
        return self.engine.behaviors()

    def awareness_state(self) -> bool:
        return self.engine.aware

    def robot_info(self) -> dict[str, Any]:
        info = super().robot_info()
        if self.config.body_sound or self.config.speaker:
            info["audio"] = audio.info(self.config.body_sound, self.config.speaker)
        return info

    def _acquire(self) -> None:
        self.pacer = Pacer(self.rate_hz)
        self.pacer.run(self.ticker(), Nap(self.stopping))  # type: ignore[arg-type]  # (an Event to the pacer)

    def ticker(self) -> Callable[[int], None]:
        """The frame loop's tick: the engine moved on to now and its frame published
        (``bench/sim_instructions.py`` counts it)."""
        stamps = Stamps()
        names, advance = self.engine.body.names, self.engine.advance  # (the model's, made once: not per frame)

        def frame(seq: int) -> None:
            now, dt = stamps.next()
            self.publish_frame(now, seq, advance(now, dt), names)

        return frame

    @property
    def frames_skipped(self) -> int:
        return self.pacer.skipped if hasattr(self, "pacer") else 0

    def metrics(self) -> dict[str, Any]:
        return {"frames_skipped": self.frames_skipped}


class Stamps:
    """A frame's ``t`` (wall clock) and the time the motion advances (monotonic) from one
    reading of the clock: ``next()`` gives both. Read apart, a thread preempted between the
    two reads (a loaded machine) made a 9.7 ms step of ``t`` carry 9.85 ms of motion, a joint
    1.5 % over its velocity limit as the frames' own clock shows it. ``t`` follows the
    monotonic clock and is pulled toward the wall clock by at most ``SLEW`` of each step (a
    speed shown at most 0.1 % off); a wall clock set by more than ``STEP_S`` is followed at once.

    >>> readings = iter([(100.0, 5.0), (100.011, 5.01), (100.0205, 5.02)])  # (wall, monotonic)
    >>> stamps = Stamps(lambda: next(readings))
    >>> [tuple(round(x, 6) for x in stamps.next()) for _ in range(2)]  # t, dt: 10 ms each, t pulled by 0.1 %
    [(100.01001, 0.01), (100.02002, 0.01)]
    """

    SLEW = 0.001   # of a step: how fast ``t`` is pulled toward the wall clock
    STEP_S = 0.5   # a wall clock this far off was set: followed at once

    def __init__(self, clocks: Callable[[], tuple[float, float]] = lambda: (time.time(), time.monotonic())) -> None:
        self._clocks = clocks
        wall, self._last = clocks()
        self._offset = wall - self._last  # t = monotonic + offset

    def next(self) -> tuple[float, float]:
        """This frame's ``t`` and the seconds since the last one, from the same reading."""
        wall, tick = self._clocks()
        dt, self._last = tick - self._last, tick
        error = wall - (tick + self._offset)
        pull = self.SLEW * max(dt, 0.0)
        self._offset += error if abs(error) > self.STEP_S else max(-pull, min(pull, error))
        return tick + self._offset, dt
