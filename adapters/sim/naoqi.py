"""The simulator's NAOqi face: fake NAOqi services on a real libqi session,
driven by the same simulated robot. Try a NAOqi configuration without a
robot, and test the ``naoqi`` adapter against it.

    [nodes.fake]
    adapter = "naoqi-sim"
    listen = "tcp://127.0.0.1:9559"

    [nodes.pepper]
    adapter = "naoqi"
    url = "tcp://127.0.0.1:9559"
"""

from __future__ import annotations

import contextlib
import logging
import random
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Literal

from sonibus.bus.adapter import Adapter
from sonibus.bus.options import bad
from sonibus.bus.pacing import Pacer
from sonibus.bus.robot import load_model, models

from .engine import SimEngine
from .naoqi_audio import ALAudioDevice
from .naoqi_services import MEMORY, QUANTITIES, SERVICES, ALBehaviorManager, ALMemory, f32

log = logging.getLogger(__name__)

BODY_TYPES = {"pepper": "Pepper", "nao": "Nao"}
DRAIN_S = 2.0  # the stop waits this long at most for the calls in flight to return


@dataclass(frozen=True)
class FakeNaoqiConfig:
    """Options of the fake NAOqi endpoint (and of the ``naoqi-sim`` adapter)."""

    listen: str = "tcp://127.0.0.1:9559"
    model: str = "pepper"
    rate_hz: float = 100.0                 # the simulated robot's motion cycle
    posture: str = "StandInit"
    idle: bool = False
    float32: bool = True                   # ALMemory stores 4-byte floats
    shuffle: bool = True                   # getBodyNames in an order that is not the joint table's
    subscriber: Literal["ok", "invalid-signature"] = "ok"   # how ALMemory.subscriber behaves
    delay_ms: float = 0.0                  # added to every call, like a network
    almemory_period_ms: float = 0.0        # ALMemory refreshed this often (NAO V6: 500); 0: every cycle
    naoqi_version: str = "2.5.10.7"        # what ALSystem.systemVersion() answers (NAO V6: 2.8.x)
    robot_name: str = "sonibus-sim"        # what ALSystem.robotName() answers
    speech_keys: Literal["at-start", "after-first-say"] = "at-start"  # when ALTextToSpeech/Text* exist in ALMemory
    freeze_after_s: float = 0.0            # stop answering calls this long after start (socket kept open); 0: never
    audio: bool = True                     # serve ALAudioDevice (microphones hear the motors; a speaker)
    mic_buffer: int = 8192                 # frames at 48 kHz per processRemote (ALAudioDevice's inputBufferSize)
    clock_offset_s: float = 0.0            # the robot's clock minus this machine's (its audio timestamps)
    played_max_s: float = 60.0             # the speaker keeps this much of what it played
    played_wav: str = ""                   # write what the speaker played there on stop (WAV); "": do not

    def __post_init__(self) -> None:
        if self.model not in models():
            raise bad("model", f"'{self.model}' is unknown — known models: {', '.join(models())}")
        if not self.listen.startswith(("tcp://", "tcps://")):
            raise bad("listen", f"'{self.listen}' is not a URL like tcp://127.0.0.1:9559")
        for key in ("delay_ms", "almemory_period_ms", "freeze_after_s"):
            if getattr(self, key) < 0:
                raise bad(key, "must be 0 or more")
        if self.mic_buffer not in (8192, 16384):
            raise bad("mic_buffer", f"{self.mic_buffer}: ALAudioDevice's inputBufferSize is 8192 or 16384")
        if not self.played_max_s > 0:
            raise bad("played_max_s", f"{self.played_max_s:g} must be more than 0")


class FakeNaoqi:
    """A fake NAOqi robot: ``start()``, ``url``, ``engine`` (the simulated robot), ``stop()``."""

    def __init__(self, config: FakeNaoqiConfig | None = None) -> None:
        self.config = config or FakeNaoqiConfig()
        self.delay_s = self.config.delay_ms / 1000.0
        self.memory: dict[str, Any] = {}
        self.engine = SimEngine(load_model(self.config.model), self._event, posture=self.config.posture,
                                idle=self.config.idle)
        names = list(self.engine.model.joint_names)
        if self.config.shuffle:
            random.Random(9559).shuffle(names)
        self.body_names = tuple(names)
        self._stop = threading.Event()
        self.answering = threading.Event()   # cleared: every call waits (a frozen robot)
        self.answering.set()
        self._thread: threading.Thread | None = None
        self._session: Any = None
        self.services: dict[str, Any] = {}
        self._calls: Counter[str] = Counter()  # calls in flight, by method (``serving``)
        self._calls_changed = threading.Condition()

    @property
    def url(self) -> str:
        return self.config.listen

    @property
    def session(self) -> Any:
        """The fake robot's libqi session (where clients' modules are found)."""
        return self._session

    def start(self) -> FakeNaoqi:
        import qi
        self._refresh()
        self.memory.update({"RobotConfig/Body/Type": BODY_TYPES[self.config.model], "DCM/CycleTime": 10})
        if self.config.speech_keys == "at-start":  # else the first speech event creates them, as on a robot
            self.memory.update({"ALTextToSpeech/TextStarted": 0, "ALTextToSpeech/TextDone": 1})
        qi.logging.setLevel(qi.logging.ERROR)  # libqi's chatter on stderr; our own log says what matters
        self._session = qi.Session()
        self._session.listenStandalone(self.config.listen)
        for service in (*SERVICES, ALAudioDevice) if self.config.audio else SERVICES:
            self.services[service.__name__] = service(self)
            self._session.registerService(service.__name__, self.services[service.__name__])
        if self.config.audio:
            self.services["ALAudioDevice"].start()
        self._thread = threading.Thread(target=self._run, name="fake-naoqi", daemon=True)
        self._thread.start()
        return self

    def freeze(self) -> None:
        """Stop answering: every call (and every call to come) waits, the connection stays open."""
        log.info("fake NAOqi at %s: frozen", self.url)
        self.answering.clear()

    def resume(self) -> None:
        self.answering.set()

    def wait_answering(self) -> bool:
        """Hold a call while the robot is frozen: True once it answers, False once it stops."""
        while not self.answering.wait(0.1) and not self._stop.is_set():
            pass
        return not self._stop.is_set()

    def until(self, finished: Callable[[], bool], what: str) -> None:
        """Hold a blocking call (``say`` until the text is spoken) until ``finished()``;
        ``RuntimeError`` once the robot stops: its engine no longer moves, so a wait
        for it would never end, and a call that libqi's thread still runs when the
        interpreter exits crashes the process."""
        while not finished():
            if self._stop.wait(0.01):
                self._check_running(what)

    def _check_running(self, what: str) -> None:
        if self._stop.is_set():
            raise RuntimeError(f"{what}: NAOqi is shutting down")

    @contextlib.contextmanager
    def serving(self, method: str) -> Iterator[None]:
        """Count a call in flight (see ``stop``); ``RuntimeError`` at once for one that comes after the stop."""
        with self._calls_changed:
            self._check_running(method)
            self._calls[method] += 1
        try:
            yield
        finally:
            with self._calls_changed:
                self._calls[method] -= 1
                self._calls_changed.notify_all()

    def stop(self) -> None:
        """Stop the robot, close its session and wait (``DRAIN_S`` at most) for the calls in
        flight to return: each ends at once (``until``, ``wait_answering``). A blocking call
        left running in one of libqi's threads (a ``say`` sent before Ctrl-C, a call held by
        a freeze) went on into the interpreter's exit, and the process ended with a
        segmentation fault or "FATAL: exception not rethrown" (issue 25)."""
        with self._calls_changed:
            self._stop.set()
        self.answering.set()
        if self._thread is not None:
            self._thread.join(2.0)
        audio: ALAudioDevice | None = self.services.get("ALAudioDevice")
        if audio is not None:
            audio.stop()
        if self._session is not None:
            self._session.close()  # no call comes in any more
        with self._calls_changed:
            if not self._calls_changed.wait_for(lambda: not +self._calls, DRAIN_S):
                log.warning("fake NAOqi at %s: calls still running %g s after its stop: %s", self.url, DRAIN_S,
                            ", ".join(f"{m} ×{n}" for m, n in (+self._calls).items()))
        self._session = None  # (freed only now: no call runs on it any more)
        if audio is not None and self.config.played_wav:
            log.info("fake NAOqi at %s: %d frames played, written to %s", self.url,
                     audio.dump(self.config.played_wav), self.config.played_wav)
        self.services.clear()  # services hold qi signals: alive at interpreter exit, libqi aborts

    def memory_value(self, key: str) -> Any:
        if key not in self.memory:
            raise RuntimeError(f"ALMemory::getData: key not found: {key}")
        return self.memory[key]

    def expand(self, names: list[str]) -> list[str]:
        if names in (["Body"], ["Joints"]):
            return list(self.body_names)
        out: list[str] = []
        for name in names:
            out.extend(self.engine.model.chain(name) or [name])
        return out

    def _run(self) -> None:
        last = last_refresh = time.monotonic()
        period = self.config.almemory_period_ms / 1000.0
        freeze_at = last + self.config.freeze_after_s if self.config.freeze_after_s else None

        def cycle(frame: int) -> None:
            nonlocal last, last_refresh, freeze_at
            tick = time.monotonic()
            self.engine.advance(time.time(), tick - last)
            last = tick
            if tick - last_refresh >= period:
                last_refresh = tick
                self._refresh()
            if freeze_at is not None and tick >= freeze_at:
                freeze_at = None
                self.freeze()

        Pacer(self.config.rate_hz).run(cycle, self._stop)

    def _refresh(self) -> None:
        """Copy the robot's state into ALMemory (as the DCM does every cycle)."""
        convert = f32 if self.config.float32 else float
        body = self.engine.body
        for i, name in enumerate(body.names):
            values = {"pos": body.positions[i], "cmd": body.targets[i], "cur": 0.1 * body.stiffness[i],
                      "temp": 35.0}
            for suffix, quantity in QUANTITIES.items():
                self.memory[MEMORY.format(name, suffix)] = convert(values[quantity])

    def _event(self, kind: str, fields: dict[str, Any]) -> None:
        memory: ALMemory | None = self.services.get("ALMemory")
        behaviors: ALBehaviorManager | None = self.services.get("ALBehaviorManager")
        if kind == "behavior" and behaviors is not None:
            signal = behaviors.behaviorStarted if fields["state"] == "started" else behaviors.behaviorStopped
            signal(fields["name"])
        elif kind == "speech" and memory is not None:
            started = fields["state"] == "started"
            memory.raise_event("ALTextToSpeech/TextDone" if started else "ALTextToSpeech/TextStarted", 0)
            memory.raise_event("ALTextToSpeech/TextStarted" if started else "ALTextToSpeech/TextDone", 1)


class NaoqiSim(Adapter):
    """A simulated Pepper or NAO served as fake NAOqi services, for the naoqi adapter."""

    Config = FakeNaoqiConfig

    def _start(self) -> None:
        self.fake = FakeNaoqi(self.config).start()
        log.info("%s: fake NAOqi %s at %s", self.name, self.config.model, self.config.listen)

    def _stop(self) -> None:
        self.fake.stop()
