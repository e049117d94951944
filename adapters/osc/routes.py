"""The OSC addresses the command gateway takes, as one table: the gateway reads it to
turn a message into a command, OSCQuery (``adapters/oscquery``) to describe each
address to sound tools (type tags, ranges, choices).

A command is ``/<robot>/cmd/<verb> args...``; ``/<robot>/cmd/joints/set/<Joint> angle
[speed]`` moves one joint, for a fader that sends one float.

>>> target = match("/pepper/cmd/joints/set/HeadYaw")
>>> target.route.path, target.robot, target.sent, target.joint
('joints/set/{joint}', 'pepper', 'joints/set/HeadYaw', 'HeadYaw')
>>> target.request([0.3])
{'names': ['HeadYaw'], 'angles': [0.3]}
>>> match("/pepper/cmd/say").route.types
's'
>>> match("/pepper/cmd/dance").route.verb   # any other verb reaches the robot, which names its verbs
'dance'
>>> match("/pepper/joints/HeadYaw") is None
True
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import zenoh

from sonibus import schemas
from sonibus.bus import keys
from sonibus.bus.commands import from_osc


@dataclass(frozen=True)
class Slot:
    """One OSC argument a client sends: its type tag, the request property it fills, and
    where the robot's info lists its values (``choices``: ``behaviors``, ``postures``,
    ``joints``, ``stiffness`` (joints and chains), ``limits`` (the joint's own range);
    ``""``: the range of the verb's schema, if any)."""

    tag: str
    name: str
    choices: str = ""


@dataclass(frozen=True)
class Route:
    """One address the gateway takes after ``/<robot>/cmd/``."""

    path: str                      # "say", "joints/set/{joint}"
    verb: str                      # the command it becomes
    slots: tuple[Slot, ...] = ()   # what a client sends; none: nothing (any arguments are ignored or optional)
    description: str = ""

    @property
    def types(self) -> str:
        """The OSC type tags a client sends (OSCQuery ``TYPE``); ``"N"`` when nothing."""
        return "".join(s.tag for s in self.slots) or "N"

    def address(self, robot: str, joint: str = "") -> str:
        return f"/{robot}/cmd/" + self.path.format(joint=joint)

    def bounds(self, slot: Slot) -> tuple[float | None, float | None]:
        """The ``(min, max)`` the verb's schema gives ``slot`` (``None``: unbounded)."""
        if self.verb not in schemas.command_verbs():
            return None, None
        prop = schemas.command_schema(self.verb).get("properties", {}).get(slot.name, {})
        return prop.get("minimum", prop.get("exclusiveMinimum")), prop.get("maximum", prop.get("exclusiveMaximum"))


def _described(verb: str) -> str:
    return schemas.command_schema(verb).get("description", "") if verb in schemas.command_verbs() else ""


ROUTES: tuple[Route, ...] = tuple(Route(path, verb, slots, _described(verb)) for path, verb, slots in (
    ("say", "say", (Slot("s", "text"),)),
    ("behavior/run", "behavior/run", (Slot("s", "name", "behaviors"),)),
    ("behavior/stop", "behavior/stop", ()),
    ("behavior/list", "behavior/list", ()),
    ("posture", "posture", (Slot("s", "name", "postures"),)),
    ("joints/set", "joints/set", (Slot("s", "names", "joints"), Slot("f", "angles"))),
    ("joints/set/{joint}", "joints/set", (Slot("f", "angles", "limits"),)),
    ("stiffness", "stiffness", (Slot("s", "names", "stiffness"), Slot("f", "value"))),
    ("awareness", "awareness", (Slot("T", "enabled"),)),
    ("stop", "stop", ()),
))
PER_JOINT = next(r for r in ROUTES if "{joint}" in r.path)
_BY_PATH = {r.path: r for r in ROUTES}


class Target(NamedTuple):
    """Where a command address leads."""

    route: Route
    robot: str
    sent: str        # the verb part as sent ("joints/set/HeadYaw"): replies go to /<robot>/reply/<sent>
    joint: str = ""  # the per-joint route's joint

    def request(self, args: Sequence[Any]) -> dict[str, Any]:
        """The command request of the message's arguments (``CommandError`` when they do not fit).
        A route that takes nothing declares ``N``: the nils a client sends for it are nothing."""
        if not self.route.slots:
            args = [a for a in args if a is not None]
        return from_osc(self.route.verb, [self.joint, *args] if self.route is PER_JOINT else args)


def match(address: str) -> Target | None:
    """``/<robot>/cmd/<verb...>`` → its ``Target`` (a verb outside the table gets a route
    of its own, without slots); None for any other address."""
    robot, sep, verb = address[1:].partition("/cmd/")
    if not address.startswith("/") or not sep:
        return None
    try:
        for chunk in (robot, *verb.split("/")):
            keys.check_name("address chunk", chunk)
        zenoh.KeyExpr(keys.command(robot, verb))
    except Exception:  # ValueError, or zenoh's ZError
        return None
    head, _, joint = verb.rpartition("/")
    if verb not in _BY_PATH and head == PER_JOINT.verb:
        return Target(PER_JOINT, robot, verb, joint)
    return Target(_BY_PATH.get(verb) or Route(verb, verb), robot, verb)
