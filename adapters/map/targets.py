"""A map's robot command: what its output or its threshold asks a robot to do.

    [nodes.moves.maps.nod]
    source = "pepper/derived/onset/speaker"
    to = [0, 0.3]                                  # HeadPitch, rad: within its limits
    target = { robot = "pepper", command = "joints/set", joint = "HeadPitch", speed = 0.6, hz = 20 }

``joints/set``: the joint follows the map's output (in the joint's unit, rad), at
``speed`` (a fraction of its maximum, the map's own cap), at most ``hz`` commands a
second. ``posture``, ``behavior/run`` and ``say``: once each time the map's
threshold turns ``on`` (so they need one), at most ``hz`` a second. The request is
a command like anyone's: the robot's owner validates it (a joint past its limits
is refused ``out_of_range`` and nothing moves).

>>> target = parse_target("maps.nod", {"robot": "pepper", "command": "joints/set", "joint": "HeadPitch"}, False)
>>> target.request(0.25)
{'names': ['HeadPitch'], 'angles': [0.25], 'speed': 0.3}
>>> parse_target("maps.hi", {"robot": "pepper", "command": "say", "text": "hello"}, True).request()
{'text': 'hello'}
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from sonibus.bus import keys, messages
from sonibus.bus.options import bad

COMMANDS = ("joints/set", "posture", "behavior/run", "say")
TRIGGERED = ("posture", "behavior/run", "say")   # sent when the threshold turns on
NEEDS = {"joints/set": "joint", "posture": "name", "behavior/run": "name", "say": "text"}
KEYS = ("robot", "command", "joint", "name", "text", "speed", "hz")
MAX_HZ = 100.0       # commands a second one map may send (a robot's own frame rate)
DEFAULT_HZ = 10.0
DEFAULT_SPEED = 0.3  # the owner's default for joints/set and posture
MAX_TEXT = 500       # say's limit (schemas/v1/cmd/say.json)


@dataclass(frozen=True, kw_only=True)
class Target:
    """A map's command to a robot: ``command`` with its ``joint``, ``name`` or ``text``,
    at ``speed`` (joints/set, posture), at most ``hz`` a second."""

    robot: str
    command: str
    joint: str = ""
    name: str = ""
    text: str = ""
    speed: float = DEFAULT_SPEED
    hz: float = DEFAULT_HZ

    @property
    def triggered(self) -> bool:
        """Sent when the map's threshold turns on (else: with each output, joints/set)."""
        return self.command in TRIGGERED

    def request(self, value: float | None = None) -> dict[str, Any]:
        """The command's arguments (``value``: the joint's angle, for joints/set)."""
        if self.command == "joints/set":
            if value is None or not math.isfinite(value):  # (a chain's output never is: checked again here)
                raise ValueError(f"joints/set {self.joint}: {value!r} is not a finite angle")
            return {"names": [self.joint], "angles": [float(value)], "speed": self.speed}
        if self.command == "posture":
            return {"name": self.name, "speed": self.speed}
        if self.command == "behavior/run":
            return {"name": self.name}
        return {"text": self.text}

    def describe(self) -> str:
        """One line for logs: ``pepper joints/set HeadPitch``."""
        what = self.joint or self.name or repr(self.text[:30])
        return f"{self.robot} {self.command} {what}"


def parse_target(where: str, table: Any, threshold: bool) -> Target:
    """A map's ``target`` table (``where``: ``maps.<map>``; ``threshold``: whether the map
    has one) as a ``Target``; ``ConfigError`` naming ``maps.<map>.target``."""
    at = f"{where}.target"
    if not isinstance(table, dict):
        raise bad(at, f"{table!r} is not a table such as {{robot = \"pepper\", command = \"joints/set\", "
                      "joint = \"HeadPitch\"}")
    for key in table:
        if key not in KEYS:
            raise bad(at, f"unknown key '{key}' — keys: {', '.join(KEYS)}")
    robot, command = table.get("robot"), table.get("command")
    if not isinstance(robot, str):
        raise bad(at, "needs robot = \"NAME\": the robot the command goes to")
    try:
        keys.check_name("robot", robot)
    except ValueError as exc:
        raise bad(at, str(exc)) from None
    if command not in COMMANDS:
        raise bad(at, f"command {command!r} is not one a map sends — commands: {', '.join(COMMANDS)}")
    needed = NEEDS[command]
    value = table.get(needed)
    if not isinstance(value, str) or not value.strip():
        raise bad(at, f"{command} needs {needed} = \"...\" (a {'joint' if needed == 'joint' else needed})")
    for key in ("joint", "name", "text"):
        if key in table and key != needed:
            raise bad(at, f"{key} is not for {command} (it takes {needed})")
    if command == "say" and len(value) > MAX_TEXT:
        raise bad(at, f"text is {len(value)} characters long, at most {MAX_TEXT}")
    if command in TRIGGERED and not threshold:
        raise bad(at, f"{command} is sent when the map's threshold turns on: give the map threshold = [ON, OFF]")
    if "speed" in table and command not in ("joints/set", "posture"):
        raise bad(at, f"speed is for joints/set and posture, not {command}")
    speed, hz = _number(at, table, "speed", DEFAULT_SPEED), _number(at, table, "hz", DEFAULT_HZ)
    if not 0 < speed <= 1:
        raise bad(at, f"speed {speed:g} must be more than 0 and at most 1 (a fraction of the joints' maximum)")
    if not 0 < hz <= MAX_HZ:
        raise bad(at, f"hz {hz:g} must be more than 0 and at most {MAX_HZ:g} (commands a second)")
    return Target(robot=robot, command=command, speed=speed, hz=hz, **{needed: value})


def _number(at: str, table: dict[str, Any], key: str, default: float) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or abs(value) > messages.MAX_VALUE:
        raise bad(at, f"{key} {value!r} is not a number")
    return float(value)
