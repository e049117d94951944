"""What a robot is doing, for the operator page's one line per robot: the behaviors it runs,
the text it says, and whether a stop holds it still, followed from the robot's own
``behavior``, ``speech`` and ``command`` events.

>>> a = follow(IDLE, "behavior", {"name": "animations/Hey_1", "state": "started"})
>>> a = follow(a, "speech", {"text": "Hello", "state": "started"})
>>> a["behaviors"], a["speaking"], a["stopped"]
(['animations/Hey_1'], 'Hello', False)
>>> follow(a, "behavior", {"name": "animations/Hey_1", "state": "stopped"})["behaviors"]
[]
>>> a = follow(IDLE, "command", {"verb": "stop", "args": {}, "ok": True})
>>> a["stopped"], follow(a, "command", {"verb": "behavior/list", "args": {}, "ok": True})
(True, None)
>>> follow(a, "command", {"verb": "posture", "args": {"name": "Stand"}, "ok": True})["stopped"]
False
>>> follow(a, "posture", {"name": "Crouch", "state": "started"}) is None
True

Its show (``<robot>/events/show``) and whether its motors rest (a ``stiffness Body 0`` it
carried out) say whether a gesture may be asked of it (``refusal``):

>>> a = follow(IDLE, "show", {"state": "closed", "next": "2026-11-29T10:00:00+01:00"})
>>> a = follow(a, "command", {"verb": "stiffness", "args": {"names": ["Body"], "value": 0.0}, "ok": True})
>>> refusal(a, "pepper", "behavior/run")
'closed: the robot rests until Sun 10:00; a supervisor may wake it (`sonibus send pepper stiffness names=Body value=1`)'
>>> refusal(follow(a, "command", {"verb": "stiffness", "args": {"names": ["Body"], "value": 1}, "ok": True}),
...         "pepper", "behavior/run") is None
True

The web node keeps it per robot shown (``robots`` message, ``activity``), so a page opened
in the middle of a behavior shows it; a robot that leaves the bus is idle again. What
the node did not hear (it started after the behavior did) is not shown.
"""

from __future__ import annotations

from typing import Any

from sonibus.bus.text import show_state

MAX_RUNNING = 8      # behaviors kept as running at once (made-up names must not grow the line)
MAX_TEXT = 200       # characters kept of a name or a text

IDLE: dict[str, Any] = {"behaviors": [], "speaking": None, "stopped": False, "show": None, "resting": False}
# What a resting robot cannot do: it would be accepted, said "running", and move no joint
NEEDS_MOTORS = ("behavior/run", "posture", "joints/set")
# Commands that move nothing: a robot held still by a stop stays so after them (any other
# command the robot carried out is its next move, and ends the hold).
STILL = ("stop", "behavior/list", "behavior/stop")


def follow(activity: dict[str, Any], kind: str, event: dict[str, Any]) -> dict[str, Any] | None:
    """``activity`` after the robot's ``event`` of ``kind`` (checked by the gate); None when
    the event does not change it."""
    state, was = event.get("state"), activity
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
    elif kind == "show":
        if state not in ("open", "closed"):
            return None
        later = event.get("next")
        changed = {**activity, "show": {"state": state, "next": str(later)[:40] if later else None}}
    elif kind == "command":
        if not event.get("ok"):  # (a refused command moved nothing)
            return None
        verb = event.get("verb")
        args = event.get("args") if isinstance(event.get("args"), dict) else {}
        if verb == "stiffness" and "Body" in (args.get("names") or ()) and isinstance(args.get("value"), int | float):
            activity = {**activity, "resting": args["value"] == 0}  # (the whole body: what the show does)
        if verb == "stop":
            changed = {**activity, "stopped": True}
        elif verb not in STILL:
            changed = {**activity, "stopped": False}
        elif activity is was:
            return None
        else:
            changed = activity
    else:
        return None
    return changed if changed != was else None


def refusal(activity: dict[str, Any], robot: str, verb: str) -> str | None:
    """Why ``verb`` is not sent to ``robot`` now: its show is closed and its motors rest (it would
    report a gesture no joint makes); None: it may be sent."""
    show = activity.get("show") or {}
    if verb not in NEEDS_MOTORS or show.get("state") != "closed" or not activity.get("resting"):
        return None
    until = show_state("closed", show.get("next")).partition(", opens")[2]
    until = f" until{until}" if until else ""
    return (f"closed: the robot rests{until}; a supervisor may wake it "
            f"(`sonibus send {robot} stiffness names=Body value=1`)")

