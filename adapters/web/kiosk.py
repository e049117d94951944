"""The kiosk's buttons: one scenario at a time, followed from the robot's events.

A press is refused while a button is under way (``busy``). A pressed button is
``running`` once its robot accepted the command (a scenario button: the robot's
show accepted the scenario, ``send``), then ``done`` when the robot's behavior
event says ``stopped`` (a say button: its speech event ``done``; a scenario button:
the show's ``scenario`` event ``ended``) or the robot was stopped (its ``command``
event of a ``stop``; for a scenario, the show says ``aborted``), or
``failed`` (refused, a behavior event ``failed``, the robot gone, or no end heard within
the button's ``timeout_s``: an event lost must not keep the kiosk busy for the rest of
the show). Every change goes
to ``announce`` as a ``button`` message; ``states`` keeps the last of each button for
a page that connects later. Runs on the web server's loop.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sonibus.bus import client
from sonibus.bus.errors import CommandError
from sonibus.bus.node import Bus
from sonibus.bus.text import show_state

from .config import Button, Kiosk


def send(bus: Bus, robot: str, button: Button, done: Callable[[client.Outcome], None], timeout: float) -> None:
    """Send what ``button`` asks of ``robot``: its command, or its scenario to the robot's show."""
    verb, args = button.command
    ask = client.ask_program if button.scenario else client.ask
    ask(bus, robot, verb, args, done, timeout)


class Stand:
    """The kiosk ``kiosk``'s buttons and the one under way."""

    def __init__(self, kiosk: Kiosk, announce: Callable[[dict[str, Any]], None]) -> None:
        self.kiosk, self.announce = kiosk, announce
        self.current: Button | None = None    # pressed, not yet done or failed
        self.accepted = False                  # the robot took its command
        self.ended: dict[str, Any] | None = None  # its end, when it came before the robot's answer
        self.states: dict[str, dict[str, Any]] = {}
        self.presses = 0                       # presses so far: which one an ``overdue`` is about
        self.show: dict[str, Any] | None = None  # the robot's show, as last said: {type: show, state, next}

    def busy(self) -> str:
        """Why a press is refused now ("" when it is not)."""
        return f"busy: {self.current.id!r} is running" if self.current is not None else ""

    def press(self, button: Button) -> int:
        """``button`` is under way; the press's number (for ``overdue``)."""
        self.current, self.accepted, self.ended = button, False, None
        self.presses += 1
        return self.presses

    def overdue(self, press: int) -> bool:
        """Press number ``press`` reached its button's ``timeout_s``: if it is still under way,
        it fails (True)."""
        button = self.current
        if button is None or press != self.presses:
            return False
        self._end("failed", f"no end heard from '{self.kiosk.robot}' within {button.timeout_s:g} s")
        return True

    def answered(self, button: Button, outcome: dict[str, Any] | CommandError, press: int | None = None) -> None:
        """The robot's answer to ``button``'s command (of press number ``press``; None: the
        current press). An answer to a press that timed out is late: it ends nothing, not
        even a new press of the same button."""
        if button is not self.current or press not in (None, self.presses):
            return
        if isinstance(outcome, CommandError):
            self._end("failed", outcome.message)
            return
        self.accepted = True
        self._say(button, "running")
        if self.ended is not None:
            self._end(**self.ended)

    def closed(self) -> str:
        """Why a press is refused while the robot's show is closed ("" when it is not)."""
        if self.show is None or self.show["state"] != "closed":
            return ""
        return show_state("closed", self.show.get("next"))

    def event(self, robot: str, kind: str, event: dict[str, Any]) -> None:
        """An event of ``robot``: its show's state, the end of the current button's scenario, or neither."""
        if robot == self.kiosk.robot and kind == "show" and event.get("state") in ("open", "closed"):
            self._show(event)
        button = self.current
        if button is None or robot != self.kiosk.robot:
            return
        end = _end_of(button, kind, event)
        if end is None:
            return
        if self.accepted:
            self._end(**end)
        elif kind != "command":  # (the end came before the robot's answer: a very short scenario)
            self.ended = end      # (but a stop heard before it came from the robot before this press)

    def robot_left(self, robot: str) -> None:
        if self.current is not None and robot == self.kiosk.robot:
            self._end("failed", f"robot '{robot}' left the bus")

    def _end(self, state: str, error: str = "") -> None:
        button, self.current = self.current, None
        if button is not None:
            self._say(button, state, error)

    def _show(self, event: dict[str, Any]) -> None:
        """Tell the kiosks the show's state when it changes; a change forgets the buttons' last
        ends (a "done" from before the close is stale once closed)."""
        later = event.get("next")
        message = {"type": "show", "state": event["state"], "next": str(later)[:40] if later else None}
        if message == self.show:
            return
        if self.show is not None and self.show["state"] != message["state"]:
            for id_, said in list(self.states.items()):
                if said["state"] != "running":
                    self.states[id_] = {"type": "button", "id": id_, "state": "idle"}
                    self.announce(self.states[id_])
        self.show = message
        self.announce(message)

    def _say(self, button: Button, state: str, error: str = "") -> None:
        message: dict[str, Any] = {"type": "button", "id": button.id, "state": state}
        if error:
            message["error"] = " ".join(error.split())
        self.states[button.id] = message
        self.announce(message)


def _end_of(button: Button, kind: str, event: dict[str, Any]) -> dict[str, str] | None:
    """How ``event`` ends ``button``'s scenario (``state``, ``error``), or None if it does not."""
    state = event.get("state")
    if button.scenario:  # (its show says how it ends: a stop of the show's own ends nothing)
        if kind == "scenario" and event.get("name") == button.scenario and state in ("ended", "aborted"):
            return {"state": "done"} if state == "ended" else {
                "state": "failed", "error": str(event.get("reason") or f"scenario '{button.scenario}' aborted")}
        return None
    if kind == "behavior" and button.behavior and event.get("name") == button.behavior:
        if state == "stopped":
            return {"state": "done"}
        if state == "failed":
            return {"state": "failed", "error": str(event.get("error") or f"behavior '{button.behavior}' failed")}
    if kind == "speech" and button.say and event.get("text") == button.say and state == "done":
        return {"state": "done"}
    if kind == "command" and event.get("verb") == "stop" and event.get("ok"):
        # (a stop ends a running behavior with its own event, but a say still queued behind another
        # text is dropped without one: the kiosk would stay busy for good)
        return {"state": "done"}
    return None
