"""What a robot is doing, for the operator page's one line per robot: the behaviors it runs,
the text it says, and whether a stop holds it still, followed from the robot's own
``behavior``, ``speech`` and ``command`` events.

>>> a = follow(IDLE, "behavior", {"name": "animations/Hey_1", "state": "started"})
>>> a = follow(a, "speech", {"text": "Hello", "state": "started"})
>>> a
{'behaviors': ['animations/Hey_1'], 'speaking': 'Hello', 'stopped': False}
>>> follow(a, "behavior", {"name": "animations/Hey_1", "state": "stopped"})
{'behaviors': [], 'speaking': 'Hello', 'stopped': False}
>>> a = follow(IDLE, "command", {"verb": "stop", "args": {}, "ok": True})
>>> a["stopped"], follow(a, "command", {"verb": "behavior/list", "args": {}, "ok": True})
(True, None)
>>> follow(a, "command", {"verb": "posture", "args": {"name": "Stand"}, "ok": True})["stopped"]
False
>>> follow(a, "posture", {"name": "Crouch", "state": "started"}) is None
True

The web node keeps it per robot shown (``robots`` message, ``activity``), so a page opened
in the middle of a behavior shows it; a robot that leaves the bus is idle again. What
the node did not hear (it started after the behavior did) is not shown.
"""

from __future__ import annotations

from typing import Any

MAX_RUNNING = 8      # behaviors kept as running at once (made-up names must not grow the line)
MAX_TEXT = 200       # characters kept of a name or a text

IDLE: dict[str, Any] = {"behaviors": [], "speaking": None, "stopped": False}
# Commands that move nothing: a robot held still by a stop stays so after them (any other
# command the robot carried out is its next move, and ends the hold).
STILL = ("stop", "behavior/list", "behavior/stop")


def follow(activity: dict[str, Any], kind: str, event: dict[str, Any]) -> dict[str, Any] | None:
    """``activity`` after the robot's ``event`` of ``kind`` (checked by the gate); None when
    the event does not change it."""
    state = event.get("state")
    if kind == "behavior":
        name = str(event.get("name", ""))[:MAX_TEXT]
        running = [b for b in activity["behaviors"] if b != name]
        if state == "started":
            running = [*running, name][-MAX_RUNNING:]
        changed = {**activity, "behaviors": running}
    elif kind == "speech":
        text = str(event.get("text", ""))[:MAX_TEXT]
        if state == "started":
            changed = {**activity, "speaking": text}
        elif state == "done" and activity["speaking"] in (text, ""):  # (another text's end ends nothing)
            changed = {**activity, "speaking": None}
        else:
            return None
    elif kind == "command":
        if not event.get("ok"):  # (a refused command moved nothing)
            return None
        verb = event.get("verb")
        if verb == "stop":
            changed = {**activity, "stopped": True}
        elif verb not in STILL:
            changed = {**activity, "stopped": False}
        else:
            return None
    else:
        return None
    return changed if changed != activity else None
