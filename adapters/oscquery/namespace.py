"""The OSCQuery namespace of robots, as pure functions: a robot's info (with the
derived entries of ``<robot>/info/derived``) and the gateway's routes become OSCQuery
methods, and a ``Tree`` of those methods renders any node as the spec's JSON.

>>> info = {"joints": [{"name": "HeadYaw", "unit": "rad", "min": -2.0, "max": 2.0, "chain": "Head"}],
...         "behaviors": ["Hey_1"], "postures": ["Stand"], "model": "pepper", "rate_hz": 50}
>>> methods = robot_methods("pepper", info)
>>> methods["/pepper/joints/HeadYaw"]["RANGE"], methods["/pepper/joints/HeadYaw"]["UNIT"]
([{'MIN': -2.0, 'MAX': 2.0}], ['angle.radian'])
>>> methods["/pepper/cmd/behavior/run"]["RANGE"], methods["/pepper/cmd/stop"]["TYPE"]
([{'VALS': ['Hey_1']}], 'N')
>>> tree = Tree(methods)
>>> sorted(tree.node("/pepper")["CONTENTS"])
['cmd', 'events', 'joints', 'program']
>>> set_ = tree.node("/pepper/cmd/joints/set")   # a method with methods below it: a container
>>> set_["TYPE"], set_["ACCESS"], list(set_["CONTENTS"])
('sf', 0, ['HeadYaw'])
>>> tree.node("/pepper/joints/HeadYaw", {"/pepper/joints/HeadYaw": [0.5]})["VALUE"]
[0.5]
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from sonibus import schemas
from sonibus.adapters.osc import routes
from sonibus.adapters.osc.profiles import EVENT_ARGS
from sonibus.bus import connection

Node = dict[str, Any]  # the OSCQuery attributes of one method (FULL_PATH and CONTENTS are the tree's)

READ, WRITE = 1, 2  # ACCESS
# What an event kind's state argument can be (docs/osc.md, "Events"); its other strings are free.
EVENT_STATES: dict[str, tuple[str, ...]] = {
    "behavior": ("started", "stopped", "failed"), "speech": ("started", "done"),
    "posture": ("started", "reached", "interrupted"), "connection": connection.SAID,
    "motion": ("onset", "offset"), "conflict": ("standby", "owner"),
    "show": ("open", "closed"), "scenario": ("started", "ended", "aborted"),
}
EVENT_HELP = {
    "behavior": "a behavior started or ended: name, state", "speech": "speech: text, state",
    "posture": "a posture: name, state", "connection": "the robot's state as its owner says it: state",
    "command": "the owner answered a command: verb, 1 (ok) or 0 (refused)",
    "motion": "a chain started or stopped moving (a features node): chain, seq, state",
    "conflict": "two owners of the robot met: state (standby, or owner again)",
    "show": "the robot's show opened or closed (a show node): state",
    "scenario": "a scenario of the robot's show started, ended or was aborted: name, state",
}
# The spec's names (OSCQueryProposal's units.md) for the units robots and processors give; a unit it has no
# name for ("fraction", "rad/s") is served as it is.
SPEC_UNITS = {"rad": "angle.radian", "deg": "angle.degree", "m": "distance.m", "cm": "distance.cm",
              "mm": "distance.mm", "m/s": "speed.m/s", "km/h": "speed.km/h", "s": "time.second", "ms": "time.ms",
              "Hz": "time.hz"}
SECTION_HELP = {"joints": "joint angles", "derived": "derived values (a features node)", "events": "events",
                "cmd": "commands, sent to the OSC gateway's port (OSC_PORT)",
                "program": "requests to the robot's show (a scenario), sent to the OSC gateway's port (OSC_PORT)"}
_TAGS = {bool: "i", int: "i", float: "f", str: "s"}  # (bools go as 0/1: event_args sends them so)
_ACCEPTS = {"s": (str,), "i": (int,), "f": (int, float)}  # the Python types a served value of a tag may have


def robot_methods(robot: str, info: Mapping[str, Any], normalized: bool = False) -> dict[str, Node]:
    """Every OSCQuery method of ``robot`` by its path: joints and derived values (read-only;
    0..1 when ``normalized``), events (read-only) and the gateway's commands (write-only).
    ``KeyError``/``TypeError``/``ValueError`` when ``info`` is not shaped as the schema says."""
    methods: dict[str, Node] = {}
    for joint in info["joints"]:
        methods[f"/{robot}/joints/{joint['name']}"] = _joint(robot, joint, normalized)
    for entry in info.get("derived", ()):
        methods[f"/{robot}/derived/{entry['name']}"] = _derived(entry, normalized)
    for kind, fields in EVENT_ARGS.items():
        methods[f"/{robot}/events/{kind}"] = _event(kind, fields, "".join("i" if f == "ok" else "s" for f in fields))
    for route in routes.ROUTES:
        if route is routes.PER_JOINT:
            for joint in info["joints"]:
                methods[route.address(robot, joint["name"])] = _command(route, info, joint)
        else:
            methods[route.address(robot)] = _command(route, info)
    return methods


def _joint(robot: str, joint: Mapping[str, Any], normalized: bool) -> Node:
    low, high = (0.0, 1.0) if normalized else (float(joint["min"]), float(joint["max"]))
    unit = str(joint["unit"])
    scale = f"0..1 of {float(joint['min']):g}..{float(joint['max']):g} {unit}" if normalized else unit
    node: Node = {"TYPE": "f", "ACCESS": READ, "VALUE": [None], "RANGE": [{"MIN": low, "MAX": high}],
                  "DESCRIPTION": f"{joint['name']} of {robot} ({scale})"}
    if not normalized:
        node["UNIT"] = [SPEC_UNITS.get(unit, unit)]
    return node


def _derived(entry: Mapping[str, Any], normalized: bool) -> Node:
    size = int(entry["size"])
    if not 1 <= size <= 64:
        raise ValueError(f"derived '{entry['name']}': size {size} is not in 1..64")
    node: Node = {"TYPE": "f" * size, "ACCESS": READ, "VALUE": [None] * size,
                  "DESCRIPTION": f"{entry['name']} ({entry['unit']})"}
    if normalized and "min" in entry:
        node["RANGE"] = [{"MIN": 0.0, "MAX": 1.0}] * size
    elif "min" in entry:
        node["RANGE"] = [{"MIN": float(entry["min"]), "MAX": float(entry["max"])}] * size
    if not (normalized and "min" in entry):
        node["UNIT"] = [SPEC_UNITS.get(str(entry["unit"]), str(entry["unit"]))] * size
    return node


def seen_event(kind: str, event: Mapping[str, Any]) -> Node:
    """The method of an event kind outside ``EVENT_ARGS`` (a features node's ``motion``), typed by
    one event of it: its fields but ``t`` and ``kind``, by name, as ``event_args`` sends them."""
    fields = sorted(k for k, v in event.items() if k not in ("t", "kind") and type(v) in _TAGS)
    return _event(kind, tuple(fields), "".join(_TAGS[type(event[f])] for f in fields))


def fits(types: str, values: Sequence[Any]) -> bool:
    """Whether ``values`` are what OSC type tags ``types`` say (``f`` takes an int too).

    >>> fits("sis", ["RArm", 7, "onset"]), fits("ss", ["Hey_1"]), fits("f", [True])
    (True, False, False)
    """
    return len(types) == len(values) and all(type(v) in _ACCEPTS.get(t, (type(v),))
                                             for t, v in zip(types, values, strict=True))


def _event(kind: str, fields: Sequence[str], types: str) -> Node:
    node: Node = {"TYPE": types, "ACCESS": READ, "VALUE": [None] * len(fields),
                  "DESCRIPTION": EVENT_HELP.get(kind) or f"{kind} events: {', '.join(fields)}"}
    ranges = [{"VALS": list(EVENT_STATES[kind])} if f == "state" and kind in EVENT_STATES
              else {"MIN": 0, "MAX": 1} if f == "ok" else {} for f in fields]
    if any(ranges):
        node["RANGE"] = ranges
    return node


def _command(route: routes.Route, info: Mapping[str, Any], joint: Mapping[str, Any] | None = None) -> Node:
    ranges = [_slot_range(route, slot, info, joint) for slot in route.slots]
    description = route.description
    if joint is not None:
        speed = schemas.command_schema(route.verb)["properties"]["speed"]
        description = (f"Move {joint['name']} to an angle ({joint['unit']}); a second float, if sent, is the speed "
                       f"(0, 1] of its maximum velocity (default {speed['default']:g}).")
    node: Node = {"TYPE": route.types, "ACCESS": WRITE, "DESCRIPTION": description,
                  # write-only: a neutral VALUE, so that parsers which want one on every method take it
                  "VALUE": [_neutral(s.tag, r) for s, r in zip(route.slots, ranges, strict=True)] or [None]}
    if any(ranges):
        node["RANGE"] = ranges
    return node


def _slot_range(route: routes.Route, slot: routes.Slot, info: Mapping[str, Any],
                joint: Mapping[str, Any] | None) -> dict[str, Any]:
    names = [str(j["name"]) for j in info["joints"]]
    if slot.choices in ("behaviors", "postures"):
        return {"VALS": [str(v) for v in info.get(slot.choices, ())]}
    if slot.choices == "joints":
        return {"VALS": names}
    if slot.choices == "stiffness":
        chains = list(dict.fromkeys(str(j["chain"]) for j in info["joints"] if j.get("chain")))
        return {"VALS": [*names, *chains, "Body"]}
    if slot.choices == "limits" and joint is not None:
        return {"MIN": float(joint["min"]), "MAX": float(joint["max"])}
    if slot.tag not in ("f", "i"):
        return {}
    low, high = route.bounds(slot)
    return {k: v for k, v in (("MIN", low), ("MAX", high)) if v is not None}


def _neutral(tag: str, span: Mapping[str, Any]) -> Any:
    if tag == "f":  # 0, or the bound nearest to it
        return min(max(0.0, span.get("MIN", -math.inf)), span.get("MAX", math.inf))
    return {"s": "", "T": False, "F": False, "i": 0}.get(tag)


class Tree:
    """The methods of every robot with the containers they imply; ``node(path)`` renders
    the spec's JSON (``CONTENTS`` below containers), ``values`` giving the current ``VALUE``s."""

    def __init__(self, methods: Mapping[str, Node]) -> None:
        self.methods = dict(methods)
        self.children: dict[str, set[str]] = {"/": set()}
        for path in self.methods:
            parent, _, name = path.rpartition("/")
            while True:
                self.children.setdefault(parent or "/", set()).add(name)
                if not parent:
                    break
                parent, _, name = parent.rpartition("/")

    def __contains__(self, path: str) -> bool:
        return path in self.methods or path in self.children

    def node(self, path: str, values: Mapping[str, Sequence[Any]] | None = None) -> Node | None:
        """The JSON object of ``path`` (``/`` the root), or None if there is no such node."""
        method, children = self.methods.get(path), self.children.get(path)
        if children is None:
            if method is None:
                return None
            node = {"FULL_PATH": path, **method}
            if values is not None and node["ACCESS"] == READ and path in values:
                node["VALUE"] = list(values[path])
            return node
        prefix = "" if path == "/" else path
        # A method with methods below it (joints/set, and joints/set/<Joint>) is served as a container
        # that keeps its TYPE, RANGE and DESCRIPTION: clients such as python-oscquery refuse a node
        # with both a VALUE and CONTENTS, and one with an ACCESS but no VALUE.
        described = {"DESCRIPTION": _container_help(path),
                     **{k: v for k, v in (method or {}).items() if k not in ("ACCESS", "VALUE")}}
        return {"FULL_PATH": path, **described, "ACCESS": 0,
                "CONTENTS": {name: self.node(f"{prefix}/{name}", values) for name in sorted(children)}}


def _container_help(path: str) -> str:
    """What a container holds, said by where it is: ``/``, ``/<robot>``, ``/<robot>/<section>``..."""
    robot, *below = path.strip("/").split("/")
    if not robot:
        return "the robots on the sonibus bus"
    if not below:
        return f"robot {robot}: its joints, derived values, events and commands"
    return f"{SECTION_HELP.get(below[0], below[0]) if len(below) == 1 else '/'.join(below)} of {robot}"
