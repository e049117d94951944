"""Robot events from NAOqi: behaviors from ``ALBehaviorManager``'s signals,
speech from ``ALTextToSpeech/TextStarted`` and ``TextDone``.

Speech arrives through ``ALMemory.subscriber(key).signal`` where the robot
allows it; where subscribing fails (qi 3.x against NAOqi 2.5 reportedly gets
"Invalid signature") the keys are polled instead, inside the frame's own read.
Neither carries the text: it is matched to the texts this adapter queued."""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from .connection import Link, RemoteError

log = logging.getLogger(__name__)

MAX_RUNNING = 64   # behaviors followed as running at once (names come from the robot: bounded)
MAX_NAME = 256     # characters kept of a behavior's name

STARTED, DONE = "ALTextToSpeech/TextStarted", "ALTextToSpeech/TextDone"

Publish = Callable[..., None]  # publish(kind, **fields)


class Speech:
    """The texts given to ``say``: waiting, then spoken (started, not yet done), in order.

    Done goes to the oldest text spoken, so a ``done`` signalled after the next
    ``started`` (two signals, two threads) still names the right text."""

    def __init__(self) -> None:
        self._waiting: deque[str] = deque()
        self._spoken: deque[str] = deque()
        self._lock = threading.Lock()

    def queue(self, text: str) -> int:
        """Add ``text``; how many utterances are ahead of it."""
        with self._lock:
            ahead = len(self._waiting) + len(self._spoken)
            self._waiting.append(text)
            return ahead

    def started(self) -> str:
        with self._lock:
            text = self._waiting.popleft() if self._waiting else ""
            self._spoken.append(text)
            return text

    def done(self) -> str:
        """The text that ended ("" for speech not ours)."""
        with self._lock:
            return self._spoken.popleft() if self._spoken else ""

    def idle(self) -> list[str]:
        """The robot is silent: every text still counted as spoken has ended."""
        with self._lock:
            texts, self._spoken = list(self._spoken), deque()
            return texts

    def reset(self) -> None:
        with self._lock:
            self._waiting.clear()
            self._spoken.clear()

    def forget(self, text: str | None = None) -> None:
        """Drop a text that will not be announced (its ``say`` returned), or (None) every waiting text."""
        with self._lock:
            if text is None:
                self._waiting.clear()
            elif text in self._waiting:
                self._waiting.remove(text)


class RobotEvents:
    """Turns NAOqi signals (or polled keys) into bus events through ``publish``."""

    def __init__(self, publish: Publish) -> None:
        self.publish = publish
        self._running: set[str] = set()  # behaviors started (their events), to tell a stop's cut from an end
        self._cut: set[str] = set()      # behaviors a stop is ending
        self._cut_lock = threading.Lock()
        self.speech = Speech()
        self.mode = "none"  # subscriber | polling
        self._last: dict[str, Any] = {}

    def attach(self, link: Link) -> tuple[str, ...]:
        """Connect to the robot's signals; the ALMemory keys to poll each frame instead."""
        self.mode, self._last = "none", {}
        self.speech.reset()  # what was spoken on an earlier connection will not be announced now
        with self._cut_lock:  # (nor is what ran then known to run now)
            self._running.clear()
            self._cut.clear()
        try:
            link.on_signal("ALBehaviorManager", "behaviorStarted", lambda name: self._behavior(name, "started"))
            link.on_signal("ALBehaviorManager", "behaviorStopped", lambda name: self._behavior(name, "stopped"))
        except RemoteError as exc:
            log.warning("no behavior events: %s", exc)
        try:
            for key in (STARTED, DONE):
                link.subscribe(key, lambda value, key=key: self._signalled(key, value))
        except RemoteError as exc:
            log.info("speech events by polling %s and %s: ALMemory.subscriber failed (%s)", STARTED, DONE, exc)
            self.mode = "polling"
            return (STARTED, DONE)
        self.mode = "subscriber"
        return ()

    def cutting(self, names: Iterable[str] | None) -> list[str]:
        """Behaviors a stop (None: every one running, as their events said) is about to end: their
        ``stopped`` says ``end: cut``; any other ``stopped`` played to its end (``finished``).
        NAOqi's ``behaviorStopped`` says neither."""
        with self._cut_lock:
            cut = sorted(self._running) if names is None else list(names)
            # (a stop of a behavior that never says it stopped must not grow it: bounded like _running)
            self._cut.update(cut[:max(0, MAX_RUNNING - len(self._cut))])
        return cut

    def _behavior(self, name: Any, state: str) -> None:
        name = str(name)[:MAX_NAME]
        with self._cut_lock:
            if state == "started" and len(self._running) < MAX_RUNNING:
                self._running.add(name)
            if state != "stopped":
                self.publish("behavior", name=name, state=state)
                return
            self._running.discard(name)
            cut = name in self._cut
            self._cut.discard(name)
        self.publish("behavior", name=name, state=state, end="cut" if cut else "finished")

    def _signalled(self, key: str, value: Any) -> None:
        if self.mode == "subscriber":
            self._changed(key, value)

    def poll(self, values: dict[str, Any]) -> None:
        """The polled keys of one frame: an event for each that turned on (the first frame sets the baseline;
        None is a key not raised yet). Two texts back to back can look like one; a silent robot ends whatever
        was counted as spoken."""
        previous, self._last = self._last, dict(values)
        if previous:
            for key in (DONE, STARTED):  # a done before the next start when both flipped
                appeared = previous.get(key) is None  # raised for the first time: a done then ends
                if values.get(key) != previous.get(key) and not (appeared and key == DONE):  # what we missed
                    self._changed(key, values.get(key))
            if values.get(DONE) and not values.get(STARTED):
                for text in self.speech.idle():
                    self.publish("speech", text=text, state="done")

    def _changed(self, key: str, value: Any) -> None:
        if not value:
            return
        if key == STARTED:
            self.publish("speech", text=self.speech.started(), state="started")
        else:
            self.publish("speech", text=self.speech.done(), state="done")
