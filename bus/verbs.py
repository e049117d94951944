"""The robot verbs as a protocol: what a robot adapter hands its owner.

``RobotVerbs`` has one method per command verb (``schemas/v1/cmd/``; "/"
becomes "_"), taking the request's arguments by the names its schema gives
them, already validated and defaulted by ``commands.validate``. Each returns the
reply's ``result`` map or raises ``CommandError``. ``METHODS`` is the one table
from verb to method; ``missing`` tells what a class lacks, so the registry
refuses such an adapter when it loads it.

>>> METHODS["joints/set"], METHODS["stop"]
('joints_set', 'stop')
>>> missing(object)[:2]
['awareness', 'behavior/list']
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, Protocol

from .. import schemas

Result = dict[str, Any]


class RobotVerbs(Protocol):
    """Carries out validated commands on one robot."""

    def awareness(self, enabled: bool) -> Result:
        """Basic awareness on or off: ``{"enabled", "previous"}``."""
        ...

    def behavior_list(self) -> Result:
        """``{"behaviors": [name, ...]}``, what ``behavior/run`` accepts."""
        ...

    def behavior_run(self, name: str) -> Result:
        """Start a behavior; fails if it is running already."""
        ...

    def behavior_stop(self, name: str | None = None) -> Result:
        """Stop one behavior, or every one: ``{"was_running"}``."""
        ...

    def joints_set(self, names: list[str], angles: list[float], speed: float) -> Result:
        """Move joints to angles (within limits) at ``speed`` × their maximum velocity:
        ``{"targets": {joint: angle}, "speed"}``, what was sent (a ROS 2 arm adds ``duration_s``)."""
        ...

    def posture(self, name: str, speed: float) -> Result:
        """Go to a posture; ``reached`` or ``interrupted`` follows as an event."""
        ...

    def say(self, text: str, volume: float | None = None, speed: float | None = None) -> Result:
        """Queue a text; ``started`` and ``done`` follow as events."""
        ...

    def stiffness(self, names: list[str], value: float) -> Result:
        """Stiffness of joints, chains or ``Body``: ``{"joints"}`` it was set on."""
        ...

    def stop(self) -> Result:
        """Halt all motion, behaviors and speech at once: what came of it, ``{"held": bool, "cut":
        [behaviors it ended], ...}`` (a ROS 2 arm: ``{"hold_sent": true}``)."""
        ...


def _methods() -> dict[str, str]:
    verb_of = {verb.replace("/", "_"): verb for verb in schemas.command_verbs()}
    declared = sorted(name for name, value in vars(RobotVerbs).items()
                      if inspect.isfunction(value) and not name.startswith("_"))
    unknown = [name for name in declared if name not in verb_of]
    if unknown or len(declared) != len(verb_of):
        raise RuntimeError(f"RobotVerbs and schemas/v1/cmd/ differ: methods {declared}, verbs {sorted(verb_of)}")
    return {verb_of[name]: name for name in declared}


METHODS: dict[str, str] = _methods()
"""Verb → method name, one entry per verb."""


def missing(cls: type) -> list[str]:
    """The verbs ``cls`` does not implement: no method, or one that does not take
    its request's arguments (``"say (takes no 'volume')"``)."""
    problems = []
    for verb, method in METHODS.items():
        if not callable(getattr(cls, method, None)):
            problems.append(verb)
        elif wrong := _wrong_arguments(cls, method, schemas.command_schema(verb)["properties"]):
            problems.append(f"{verb} ({wrong})")
    return problems


def bind(verbs: object) -> dict[str, Callable[..., Result]]:
    """``verbs``'s method for each verb; ``TypeError`` if it lacks one."""
    if lacking := missing(type(verbs)):
        raise TypeError(f"{type(verbs).__name__} does not implement {', '.join(lacking)} (see RobotVerbs)")
    return {verb: getattr(verbs, method) for verb, method in METHODS.items()}


def _wrong_arguments(cls: type, method: str, arguments: dict[str, Any]) -> str:
    try:
        parameters = list(inspect.signature(getattr(cls, method)).parameters.values())
    except (TypeError, ValueError):  # a builtin without a signature: trust it
        return ""
    if inspect.isfunction(inspect.getattr_static(cls, method)):
        parameters = parameters[1:]  # self
    if any(p.kind is p.VAR_KEYWORD for p in parameters):
        return ""
    named = {p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    if absent := [a for a in arguments if a not in named]:
        return "takes no " + ", ".join(f"'{a}'" for a in absent)
    if extra := [p.name for p in parameters if p.default is p.empty and p.name not in arguments
                 and p.kind is not p.VAR_POSITIONAL]:
        return "needs " + ", ".join(f"'{e}'" for e in extra) + ", not an argument of the request"
    return ""
