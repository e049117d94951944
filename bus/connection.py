"""A robot's connection state, as its owner knows it, said the same way everywhere.

``connecting``: not reached yet (the first try is under way); ``connected``: it
answers and frames flow; ``not_answering``: the link is up but no frame came for
a while (a frozen or overloaded robot); ``lost``: it cannot be reached (the owner
retries); ``standby``: another owner keeps the robot (``bus/ownership.py``).

The owner (``RobotAdapter``) keeps one ``Connection``: its info says it
(``connection``: state, since, error, frames_per_s: the frames it really
published over the last second, 0 when none), and each change goes out as the
event ``<robot>/events/connection``. A command other than ``stop`` to a robot
that is not connected is refused with ``not_connected`` or ``not_answering``.

>>> describe({"state": "lost", "error": "connect: Connection refused", "frames_per_s": 0.0})
'NOT CONNECTED: lost (connect: Connection refused)'
>>> describe({"state": "connected", "frames_per_s": 49.7})
'connected'
>>> describe({})  # an owner that does not say (a replay): it publishes, so it is there
'connected'
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

from .errors import CommandError

STATES = ("connecting", "connected", "not_answering", "lost", "standby")
SAID = STATES[:4]
"""The states a ``connection`` event carries (``standby`` is in the info only: the owner speaks for the robot)."""
REFUSALS = {"connecting": "not_connected", "lost": "not_connected", "not_answering": "not_answering"}
"""The code a command gets in each state that is not ``connected`` (``standby``: ``conflict``, by the ownership)."""
UNREACHED = frozenset(REFUSALS.values())
RATE_WINDOW_S = 1.0
SHOWN = {"connected": "connected", "connecting": "NOT CONNECTED: connecting", "lost": "NOT CONNECTED: lost",
         "not_answering": "NOT ANSWERING", "standby": "STANDBY: another owner keeps it"}


def state_of(info: dict[str, Any] | None) -> dict[str, Any]:
    """The ``connection`` of a robot's info, its fields checked (it came from the network);
    an owner that does not say (a replay, an older owner) publishes what it has, so it
    counts as connected.

    >>> state_of({"connection": {"state": "lost", "error": 7, "since": 1.5}})
    {'state': 'lost', 'since': 1.5}
    """
    found = (info or {}).get("connection") if isinstance(info, dict) else None
    if not isinstance(found, dict) or found.get("state") not in STATES:
        return {"state": "connected"}
    checked: dict[str, Any] = {"state": found["state"]}
    for key in ("since", "frames_per_s"):
        value = found.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
            checked[key] = float(value)
    if isinstance(found.get("error"), str) and found["error"]:
        checked["error"] = " ".join(found["error"].split())[:300]
    return checked


def describe(connection: dict[str, Any]) -> str:
    """One short text of a ``connection`` (upper case when it is not connected), with its error."""
    state = connection.get("state", "connected")
    error = connection.get("error") or ""
    shown = SHOWN.get(state, state)
    return f"{shown} ({error})" if error and state != "connected" else shown


def rate(info: dict[str, Any] | None) -> float:
    """The frames per second a robot's owner really publishes (its info's ``rate_hz``,
    what it asks of the robot, when the owner does not say)."""
    found = state_of(info).get("frames_per_s")
    if found is not None:
        return float(found)
    asked = (info or {}).get("rate_hz")
    return float(asked) if isinstance(asked, int | float) and math.isfinite(asked) else 0.0


class FrameRate:
    """Frames per second over the last ``RATE_WINDOW_S``, 0 once none came for that long;
    ``add`` from the frame loop (cheap: one count), ``per_s`` from anywhere."""

    def __init__(self) -> None:
        self._start = self._last = -math.inf
        self._count, self._rate = 0, 0.0

    def add(self, now: float) -> None:
        if now - self._last > RATE_WINDOW_S:  # after a pause: a new count
            self._start, self._count, self._rate = now, 0, 0.0
        self._last = now
        self._count += 1
        if now - self._start >= RATE_WINDOW_S:
            self._rate = (self._count - 1) / (now - self._start)
            self._start, self._count = now, 1

    def per_s(self, now: float) -> float:
        if now - self._last > RATE_WINDOW_S:
            return 0.0
        if self._rate:
            return self._rate
        return (self._count - 1) / (now - self._start) if now > self._start and self._count > 1 else 0.0


class Connection:
    """One robot's state, said through ``publish(fields)`` (the owner's ``connection``
    event) each time it changes. ``answered()`` for each frame read from the robot:
    with ``answer_s``, a connected robot that read none for that long is
    ``not_answering`` (``check``, from a worker) until the next one."""

    def __init__(self, publish: Callable[[dict[str, Any]], None], state: str = "connecting",
                 answer_s: float | None = None) -> None:
        self.publish, self.answer_s = publish, answer_s
        self.state, self.since, self.error = state, time.time(), ""
        self.details: dict[str, Any] = {}
        self.rate = FrameRate()
        self._answered = time.monotonic()
        self._lock = threading.Lock()

    def set(self, state: str, error: str = "", **details: Any) -> bool:
        """Change the state (``error``: why it is not connected; ``details``: more fields for
        the event, e.g. ``url``); said once per change. Whether it changed."""
        if state not in STATES:
            raise ValueError(f"connection state {state!r}: one of {', '.join(STATES)}")
        with self._lock:
            if state == self.state and error == self.error:
                return False
            was, self.state, self.since, self.error = self.state, state, time.time(), error
            self.details = details
            if state == "connected":
                self._answered = time.monotonic()
        if state != was:
            self.announce()
        return state != was

    def announce(self) -> None:
        """Say the state as it is now (the owner's first one, at start)."""
        with self._lock:
            fields = {"state": self.state, **self.details, **({"error": self.error} if self.error else {})}
        self.publish(fields)

    def answered(self, now: float) -> None:
        """A frame came from the robot (``now``: monotonic)."""
        self._answered = now
        if self.state == "not_answering":
            self.set("connected")

    def answered_since(self, since: float, stopping: threading.Event | None = None) -> bool:
        """Whether the robot answered (a frame came) after ``since`` (monotonic), waiting for it
        ``answer_s`` at most: a call sent without waiting for its answer (NAOqi's ``say``,
        which returns once spoken) is known to have reached a robot that answers."""
        deadline = since + (self.answer_s or 0.0)
        while self._answered <= since:
            if time.monotonic() >= deadline or (stopping is not None and stopping.is_set()):
                return False
            time.sleep(0.005)
        return True

    def published(self, now: float) -> None:
        """A frame went out on the bus (counted in ``frames_per_s``)."""
        self.rate.add(now)

    def check(self, now: float) -> None:
        """``not_answering`` once a connected robot gave no frame for ``answer_s``."""
        silent = now - self._answered
        if self.answer_s is not None and self.state == "connected" and silent >= self.answer_s:
            self.set("not_answering", f"no frame from the robot for {silent:.1f} s; the link is up")

    def due_in(self, now: float) -> float:
        """Seconds until ``check`` may find the robot silent (``now``: monotonic): ``answer_s``
        after its last frame while connected; else ``answer_s`` (the soonest a robot that
        connects now can fall silent, its connection counting as an answer)."""
        if self.answer_s is None:
            return 1.0
        if self.state != "connected":
            return self.answer_s
        return max(0.005, self._answered + self.answer_s - now)  # (at least a little: no spin on a rounding)

    def info(self, standing_by: bool = False) -> dict[str, Any]:
        """What the robot's info says of it (``standing_by``: another owner keeps it)."""
        now = time.monotonic()
        with self._lock:
            state, since, error = ("standby" if standing_by else self.state), self.since, self.error
        shown = {"state": state, "since": round(since, 3), "frames_per_s": round(self.rate.per_s(now), 1)}
        if error and state != "standby":
            shown["error"] = error
        return shown

    def refusal(self, verb: str, robot: str, hint: str = "") -> CommandError | None:
        """The typed error a command gets now (None when the robot is connected)."""
        with self._lock:
            state, since, error = self.state, self.since, self.error
        code = REFUSALS.get(state)
        if code is None:
            return None
        what = "does not answer" if code == "not_answering" else f"is not connected ({state})"
        ago = _ago(time.time() - since)
        return CommandError(code, f"{verb}: robot '{robot}' {what} since {ago}{f': {error}' if error else ''}; "
                                  f"nothing was sent{f' — {hint}' if hint else ''}")


def _ago(seconds: float) -> str:
    """``4.2 s``, ``3 min``.

    >>> _ago(4.23), _ago(185)
    ('4.2 s', '3 min')
    """
    return f"{seconds:.1f} s" if seconds < 90 else f"{seconds / 60:.0f} min"
