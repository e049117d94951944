"""JSON Schemas of every message on the bus, versioned (``v1/``).

>>> from sonibus import schemas
>>> schemas.validate("joint_sample", {"t": 1.0, "seq": 0, "v": 0.1})
>>> schemas.command_verbs()[:2]
('awareness', 'behavior/list')
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

import jsonschema

VERSION = 1

__all__ = ["VERSION", "command_schema", "command_verbs", "load", "validate", "validator"]


def _root() -> Any:
    return resources.files(__package__).joinpath(f"v{VERSION}")


@cache
def load(name: str) -> dict[str, Any]:
    """The schema called ``name``: ``joint_sample``, ``event``, ``robot_info``,
    ``command_reply`` or ``cmd/<verb>`` (e.g. ``cmd/joints/set``)."""
    if name.startswith("cmd/"):
        path = _root().joinpath("cmd", name[4:].replace("/", ".") + ".json")
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
def command_verbs() -> tuple[str, ...]:
    """Every command verb that has a request schema, sorted."""
    files = _root().joinpath("cmd").iterdir()
    return tuple(sorted(f.name[:-5].replace(".", "/") for f in files if f.name.endswith(".json")))


def command_schema(verb: str) -> dict[str, Any]:
    return load("cmd/" + verb)
