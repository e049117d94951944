"""The command verbs as NAOqi calls (``sonibus.bus.verbs.RobotVerbs``). Requests
arrive validated (``RobotAdapter``); what can block on the robot (``say``,
``goToPosture``) is sent and not waited for, everything else is waited for at
most the connect timeout.

Errors: a robot that refuses → ``failed`` with its message on one line; no
robot → ``not_connected``; a call it did not answer in time → ``not_answering``.
A ``stop`` that could not reach the robot is kept (``stop_pending``) and sent as
soon as the robot answers again (``send_pending_stop``, on the next connection)."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from sonibus.bus.commands import expand_stiffness_names
from sonibus.bus.errors import CommandError
from sonibus.bus.robot import RobotModel

from .awareness import Awareness
from .connection import Link, LinkDown, RemoteError, one_line
from .events import RobotEvents

log = logging.getLogger(__name__)

STOP_CALLS = (("ALBehaviorManager", "stopAllBehaviors"), ("ALMotion", "killAll"), ("ALMotion", "stopMove"),
              ("ALTextToSpeech", "stopAll"))
RESTORE_TIMEOUT_MS = 800  # on stop: the node must end within about a second
UNANSWERED_STOP_MS = 1000  # a stop sent to a robot that does not answer waits this long for it, not the connect timeout


class Postures:
    """The posture in progress: ``started``, then ``reached`` or ``interrupted``."""

    def __init__(self, publish: Callable[..., None]) -> None:
        self.publish = publish
        self._current: tuple[str, object] | None = None
        self._lock = threading.Lock()

    def begin(self, name: str) -> object:
        token = object()
        with self._lock:
            self._end("interrupted")
            self._current = (name, token)
            self.publish("posture", name=name, state="started")
        return token

    def interrupt(self) -> None:
        with self._lock:
            self._end("interrupted")

    def finished(self, token: object, reached: bool) -> None:
        with self._lock:
            if self._current is not None and self._current[1] is token:
                self._end("reached" if reached else "interrupted")

    def _end(self, state: str) -> None:
        if self._current is not None:
            self.publish("posture", name=self._current[0], state=state)
            self._current = None


class NaoqiCommands:
    """Carries out validated commands on the robot behind ``link``."""

    def __init__(self, link: Link, events: RobotEvents, model: Callable[[], RobotModel],
                 down: Callable[[str], CommandError], answering: Callable[[], bool] = lambda: True,
                 answered_since: Callable[[float], bool] = lambda since: True) -> None:
        self.link, self.events, self.model, self.down, self.answering = link, events, model, down, answering
        self.answered_since = answered_since  # (whether the robot answered anything after a time, waiting a bit)
        self._stop_wanted = False          # a stop was asked and the robot has not done it yet
        self._stop_sent: list[Any] = []    # ... its calls, sent to a robot that did not answer them (futures)
        self.postures = Postures(events.publish)
        self.installed: tuple[str, ...] = ()  # behaviors, as the robot last listed them
        self.voice_defaults: dict[str, float] = {}
        self._voice: dict[str, float] = {}
        self._awareness_paused = False   # by this adapter, to be resumed on stop
        self.aware = Awareness(link)     # whether it is on now, for the info
        self._paused_before: bool | None = None

    @property
    def stop_pending(self) -> bool:
        """A stop that did not reach the robot: sent again on the next connection (``send_pending_stop``),
        unless the robot answered its calls meanwhile (it was frozen, not gone)."""
        sent = self._stop_sent
        return self._stop_wanted and not (sent and all(f.isFinished() and not f.hasError() for f in sent))

    def connected(self, behaviors: Sequence[str]) -> None:
        """A (new) connection: its behaviors, and the voice settings it has now (the first ones are the defaults)."""
        self.installed = tuple(behaviors)
        current = {"volume": self.link.try_call("ALTextToSpeech", "getVolume"),
                   "speed": self.link.try_call("ALTextToSpeech", "getParameter", "speed")}
        self._voice = {k: float(v) for k, v in current.items() if isinstance(v, int | float)}
        for key, value in self._voice.items():
            self.voice_defaults.setdefault(key, value)

    def _call(self, verb: str, service: str, method: str, *args: Any) -> Any:
        """Call and wait for the answer."""
        return self._failed(verb, self.link.call, service, method, *args)

    def _send(self, verb: str, service: str, method: str, *args: Any) -> Any:
        """Send a call that may block on the robot; its future."""
        return self._failed(verb, self.link.start, service, method, *args)

    def _failed(self, verb: str, how: Callable[..., Any], *args: Any) -> Any:
        try:
            return how(*args)
        except LinkDown as exc:
            if not self.link.connected:
                raise self.down(f"{verb}: {exc}") from None
            if "no answer within" in str(exc):  # a live link, a robot that does not answer
                raise CommandError("not_answering", f"{verb}: robot does not answer: {exc}") from None
            raise CommandError("failed", f"{verb}: {exc}") from None
        except RemoteError as exc:
            raise CommandError("failed", f"{verb}: {exc}") from None

    # -- verbs ------------------------------------------------------------------------

    def behavior_list(self) -> dict[str, Any]:
        """Asks the robot again: behaviors installed since it connected show up."""
        if self.link.connected:
            try:
                self.installed = tuple(sorted(self.link.call("ALBehaviorManager", "getInstalledBehaviors")))
            except (LinkDown, RemoteError) as exc:
                log.debug("behavior list: %s", exc)
        return {"behaviors": list(self.installed)}

    def behavior_run(self, name: str) -> dict[str, Any]:
        if self._call("behavior/run", "ALBehaviorManager", "isBehaviorRunning", name):
            raise CommandError("failed", f"behavior '{name}' is already running")
        self.postures.interrupt()
        self._call("behavior/run", "ALBehaviorManager", "startBehavior", name)
        return {"name": name}

    def behavior_stop(self, name: str | None = None) -> dict[str, Any]:
        self.events.cutting(None if name is None else [name])
        if name is None:
            running = bool(self._call("behavior/stop", "ALBehaviorManager", "getRunningBehaviors"))
            self._call("behavior/stop", "ALBehaviorManager", "stopAllBehaviors")
        else:
            running = bool(self._call("behavior/stop", "ALBehaviorManager", "isBehaviorRunning", name))
            if running:
                self._call("behavior/stop", "ALBehaviorManager", "stopBehavior", name)
        return {"was_running": running}

    def joints_set(self, names: list[str], angles: list[float], speed: float) -> dict[str, Any]:
        self._call("joints/set", "ALMotion", "setAngles", list(names), [float(a) for a in angles], float(speed))
        self.postures.interrupt()
        return {"targets": dict(zip(names, map(float, angles), strict=True)), "speed": speed}  # (sent: NAOqi's own)

    def posture(self, name: str, speed: float) -> dict[str, Any]:
        sent = time.monotonic()
        future = self._send("posture", "ALRobotPosture", "goToPosture", name, float(speed))
        token = self.postures.begin(name)
        future.then(lambda done: self._posture_done(name, token, done))
        self._heard_after("posture", sent)
        return {"name": name}

    def _heard_after(self, verb: str, sent: float) -> None:
        """A call sent and not waited for (it returns once done) is answered ok only once the
        robot answered something after it: one that froze a moment ago gets ``not_answering``."""
        if not self.answered_since(sent):
            raise CommandError("not_answering", f"{verb}: sent, but the robot has not answered anything since: it "
                                                f"does not answer (it may still do it if it answers again)")

    def _posture_done(self, name: str, token: object, future: Any) -> None:
        if future.hasError():
            log.warning("posture %s: %s", name, one_line(future.error()))
        self.postures.finished(token, not future.hasError() and bool(future.value()))

    def say(self, text: str, volume: float | None = None, speed: float | None = None) -> dict[str, Any]:
        for key, method, value in (("volume", "setVolume", volume), ("speed", "setParameter", speed)):
            wanted = value if value is not None else self.voice_defaults.get(key)  # per text, like the sim
            if wanted is not None and float(wanted) != self._voice.get(key):
                self._call("say", "ALTextToSpeech", method, *(("speed",) if key == "speed" else ()), float(wanted))
                self._voice[key] = float(wanted)
        ahead = self.events.speech.queue(text)
        sent = time.monotonic()
        try:
            future = self._send("say", "ALTextToSpeech", "say", text)
        except CommandError:
            self.events.speech.forget(text)
            raise
        future.then(lambda done: self._said(text, done))
        self._heard_after("say", sent)
        return {"queued": ahead}

    def _said(self, text: str, future: Any) -> None:
        self.events.speech.forget(text)  # spoken (its events came) or dropped (they never will)
        if future.hasError():
            log.warning("say %r: %s", text[:40], one_line(future.error()))

    def stiffness(self, names: list[str], value: float) -> dict[str, Any]:
        joints = expand_stiffness_names(names, self.model())
        self._call("stiffness", "ALMotion", "setStiffnesses", joints, float(value))
        return {"joints": joints}

    def awareness(self, enabled: bool) -> dict[str, Any]:
        previous = bool(self._call("awareness", "ALBasicAwareness", "isEnabled"))
        self._call("awareness", "ALBasicAwareness", "setEnabled", bool(enabled))
        if enabled and self._awareness_paused:  # turned on by hand: no longer held paused
            self._call("awareness", "ALBasicAwareness", "resumeAwareness")
            self._awareness_paused = False
        self.aware.took(enabled)
        return {"enabled": enabled, "previous": previous}

    def stop(self) -> dict[str, Any]:
        """Every part is sent at once and each is waited for, whatever the others do (at most
        ``UNANSWERED_STOP_MS`` on a robot that does not answer). Not reached: kept for later."""
        self.events.speech.forget()
        cut = self.events.cutting(None)
        self.postures.interrupt()
        self._stop_wanted, self._stop_sent = True, []  # (until the robot has done every part)
        wait_ms = None if self.answering() else UNANSWERED_STOP_MS
        sent, failures, unanswered = [], [], []
        for service, method in STOP_CALLS:
            try:
                sent.append((f"{service}.{method}", self.link.start(service, method)))
            except (LinkDown, RemoteError) as exc:
                failures.append(f"{service}.{method}: {exc}")
        for what, future in sent:
            try:
                self.link.wait(future, what, wait_ms)
            except LinkDown as exc:
                unanswered.append(str(exc))
            except RemoteError as exc:
                failures.append(str(exc))
        if not self.link.connected:
            raise self.down("stop")
        if unanswered:  # sent: the robot does them if it answers again, else they go again on the next connection
            self._stop_sent = [future for _, future in sent]
            raise CommandError("not_answering", f"stop: robot does not answer: {'; '.join(unanswered)}")
        self._stop_wanted = False
        if failures:
            raise CommandError("failed", f"stop: {'; '.join(failures)} (the other parts were done)")
        # (every part answered: motion killed and still, behaviors and speech stopped; `cut`: the behaviors
        # running as their events said)
        return {"held": True, "cut": cut}

    def send_pending_stop(self) -> None:
        """On a new connection: the stop asked for while the robot could not be reached."""
        if not self.stop_pending:
            return
        failures = []
        for service, method in STOP_CALLS:
            try:
                self.link.call(service, method)
            except (LinkDown, RemoteError) as exc:
                failures.append(f"{service}.{method}: {exc}")
        self._stop_wanted, self._stop_sent = bool(failures) and not self.link.connected, []
        log.warning("sent the stop asked for while the robot could not be reached%s",
                    f" — failed: {'; '.join(failures)}" if failures else "")

    # -- awareness held paused while the adapter runs ---------------------------------

    def pause_awareness(self) -> None:
        if self._paused_before is None:  # the state to restore is the one before the first pause
            self._paused_before = bool(self.link.try_call("ALBasicAwareness", "isAwarenessPaused"))
        self.link.call("ALBasicAwareness", "pauseAwareness")
        self._awareness_paused = True

    def restore_awareness(self) -> None:
        if self._awareness_paused and not self._paused_before and self.link.connected:
            self.link.call("ALBasicAwareness", "resumeAwareness", timeout_ms=RESTORE_TIMEOUT_MS,
                           interruptible=False)  # called while stopping: bounded by its own timeout
        self._awareness_paused = False
