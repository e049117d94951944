"""What a robot is doing, for the operator page's one line per robot: the behaviors it runs
and the text it says, followed from the robot's own ``behavior`` and ``speech`` events.

>>> a = follow(IDLE, "behavior", {"name": "animations/Hey_1", "state": "started"})
>>> a = follow(a, "speech", {"text": "Hello", "state": "started"})
>>> a
{'behaviors': ['animations/Hey_1'], 'speaking': 'Hello'}
>>> follow(a, "behavior", {"name": "animations/Hey_1", "state": "stopped"})
{'behaviors': [], 'speaking': 'Hello'}
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

IDLE: dict[str, Any] = {"behaviors": [], "speaking": None}


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
    else:
        return None
    return changed if changed != activity else None
