"""JSON Schemas of every message on the bus, versioned (``v1/``).

>>> from sonibus import schemas
>>> schemas.validate("joint_sample", {"t": 1.0, "seq": 0, "v": 0.1})
>>> schemas.command_verbs()[:2]
('awareness', 'behavior/list')
>>> schemas.program_verbs()
('scenario', 'status')
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

import jsonschema

VERSION = 1

__all__ = ["REQUESTS", "VERSION", "command_schema", "command_verbs", "load", "program_schema", "program_verbs",
           "request_schema", "request_verbs", "validate", "validator"]

REQUESTS = ("cmd", "program", "maps")  # the sections whose keys take requests: a robot's commands, a program's,
                                      # a map node's (``<node>/maps/<verb>``: edit its maps while they run)


def _root() -> Any:
    return resources.files(__package__).joinpath(f"v{VERSION}")


@cache
def load(name: str) -> dict[str, Any]:
    """The schema called ``name``: ``joint_sample``, ``event``, ``robot_info``,
    ``command_reply``, ``cmd/<verb>`` (e.g. ``cmd/joints/set``) or ``program/<verb>``."""
    section, _, verb = name.partition("/")
    if section in REQUESTS and verb:
        path = _root().joinpath(section, verb.replace("/", ".") + ".json")
    else:
        path = _root().joinpath(name + ".json")
    if not path.is_file():
        raise KeyError(f"no schema '{name}'")
    return json.loads(path.read_text(encoding="utf-8"))


@cache
def validator(name: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(load(name))


def validate(name: str, message: Any) -> None:
    """Raise ``jsonschema.ValidationError`` if ``message`` does not fit schema ``name``."""
    validator(name).validate(message)


@cache
def request_verbs(section: str) -> tuple[str, ...]:
    """Every verb of ``section`` (``cmd``, ``program``) that has a request schema, sorted."""
    files = _root().joinpath(section).iterdir()
    return tuple(sorted(f.name[:-5].replace(".", "/") for f in files if f.name.endswith(".json")))


def request_schema(section: str, verb: str) -> dict[str, Any]:
    return load(f"{section}/{verb}")


def command_verbs() -> tuple[str, ...]:
    """Every command verb (what a robot's owner serves) that has a request schema, sorted."""
    return request_verbs("cmd")


def command_schema(verb: str) -> dict[str, Any]:
    return request_schema("cmd", verb)


def program_verbs() -> tuple[str, ...]:
    """Every verb a program that drives a robot (a show) serves on ``<robot>/program/<verb>``, sorted."""
    return request_verbs("program")


def program_schema(verb: str) -> dict[str, Any]:
    return request_schema("program", verb)
