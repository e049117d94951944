"""The OSC addresses the command gateway takes, as one table: the gateway reads it to
turn a message into a command, OSCQuery (``adapters/oscquery``) to describe each
address to sound tools (type tags, ranges, choices).

A command is ``/<robot>/cmd/<verb> args...``; ``/<robot>/cmd/joints/set/<Joint> angle
[speed]`` moves one joint, for a fader that sends one float. A request to the program
that drives the robot (its show) is ``/<robot>/program/<verb> args...``:
``/pepper/program/scenario "story"`` starts a scenario.

>>> target = match("/pepper/cmd/joints/set/HeadYaw")
>>> target.route.path, target.robot, target.sent, target.joint
('joints/set/{joint}', 'pepper', 'joints/set/HeadYaw', 'HeadYaw')
>>> target.request([0.3])
{'names': ['HeadYaw'], 'angles': [0.3]}
>>> match("/pepper/cmd/say").route.types
's'
>>> match("/pepper/cmd/dance").route.verb   # any other verb reaches the robot, which names its verbs
'dance'
>>> target = match("/pepper/program/scenario")
>>> target.route.section, target.request(["story"])
('program', {'name': 'story'})
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
    """One address the gateway takes after ``/<robot>/cmd/`` (or ``/<robot>/program/``)."""

    path: str                      # "say", "joints/set/{joint}"
    verb: str                      # the command it becomes
    slots: tuple[Slot, ...] = ()   # what a client sends; none: nothing (any arguments are ignored or optional)
    description: str = ""
    section: str = "cmd"           # cmd: a command to the robot's owner; program: a request to its show

    @property
    def types(self) -> str:
        """The OSC type tags a client sends (OSCQuery ``TYPE``); ``"N"`` when nothing."""
        return "".join(s.tag for s in self.slots) or "N"

    def address(self, robot: str, joint: str = "") -> str:
        return f"/{robot}/{self.section}/" + self.path.format(joint=joint)

    def bounds(self, slot: Slot) -> tuple[float | None, float | None]:
        """The ``(min, max)`` the verb's schema gives ``slot`` (``None``: unbounded)."""
        if self.verb not in schemas.request_verbs(self.section):
            return None, None
        prop = schemas.request_schema(self.section, self.verb).get("properties", {}).get(slot.name, {})
        return prop.get("minimum", prop.get("exclusiveMinimum")), prop.get("maximum", prop.get("exclusiveMaximum"))


def _described(verb: str, section: str = "cmd") -> str:
    known = verb in schemas.request_verbs(section)
    return schemas.request_schema(section, verb).get("description", "") if known else ""


ROUTES: tuple[Route, ...] = (*(Route(path, verb, slots, _described(verb)) for path, verb, slots in (
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
)), Route("scenario", "scenario", (Slot("s", "name"),), _described("scenario", "program"), "program"))
PER_JOINT = next(r for r in ROUTES if "{joint}" in r.path)
_BY_PATH = {(r.section, r.path): r for r in ROUTES}


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
        return from_osc(self.route.verb, [self.joint, *args] if self.route is PER_JOINT else args,
                        section=self.route.section)


def match(address: str) -> Target | None:
    """``/<robot>/cmd/<verb...>`` (or ``/<robot>/program/<verb...>``) → its ``Target`` (a
    verb outside the table gets a route of its own, without slots); None for any other address."""
    robot, _, rest = address[1:].partition("/")
    section, _, verb = rest.partition("/")
    if not address.startswith("/") or section not in ("cmd", "program") or not verb:
        return None
    try:
        for chunk in (robot, *verb.split("/")):
            keys.check_name("address chunk", chunk)
        zenoh.KeyExpr(keys.command(robot, verb))
    except Exception:  # ValueError, or zenoh's ZError
        return None
    head, _, joint = verb.rpartition("/")
    if section == "cmd" and (section, verb) not in _BY_PATH and head == PER_JOINT.verb:
        return Target(PER_JOINT, robot, verb, joint)
    route = _BY_PATH.get((section, verb)) or Route(verb, verb, section=section)
    return Target(route, robot, verb)
