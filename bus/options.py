"""Typed options: build a config dataclass from a plain mapping (TOML, CLI).

Unknown keys and wrong types raise ``ConfigError`` naming where and the key.

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Opts:
...     rate_hz: float = 100.0
>>> from_mapping(Opts, {"rate_hz": 50}, "show.toml [nodes.pepper]")
Opts(rate_hz=50.0)
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

from .errors import ConfigError

T = TypeVar("T")


def from_mapping(cls: type[T], data: Mapping[str, Any], where: str,
                 lines: Mapping[str, int] | None = None) -> T:
    """An instance of dataclass ``cls`` from ``data``, checked key by key.

    ``lines`` maps keys to their line in the source file, for the messages."""
    def at(key: str) -> str:
        return located(where, lines, key)

    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    hints = typing.get_type_hints(cls)
    for key in data:
        if key not in fields:
            raise ConfigError(f"{at(key)}: unknown key '{key}' — known keys: {', '.join(fields) or 'none'}")
    missing = [n for n, f in fields.items() if n not in data and f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ConfigError(f"{where}: missing key '{missing[0]}'")
    values = {key: coerce(value, hints[key], f"{at(key)}: key '{key}'") for key, value in data.items()}
    try:
        return cls(**values)
    except ConfigError as exc:  # from the dataclass's own checks: "key 'rate_hz': ..."
        named = re.match(r"key '([^']+)'", str(exc))
        raise ConfigError(f"{at(named[1]) if named else where}: {exc}") from None
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{where}: {exc}") from exc


def bad(key: str, problem: str) -> ConfigError:
    """The error a config dataclass raises for one of its keys (``from_mapping``
    adds the file, table and line)."""
    return ConfigError(f"key '{key}': {problem}")


def located(where: str, lines: Mapping[str, int] | None, key: str) -> str:
    """``where`` plus the line that sets ``key``, when known (a dotted key of a sub-table,
    ``maps.cutoff.curve``, falls back to the line of the nearest table that holds it)."""
    while lines:
        if key in lines:
            return f"{where} line {lines[key]}"
        key, dot, _ = key.rpartition(".")
        if not dot:
            break
    return where


def coerce(value: Any, tp: Any, where: str) -> Any:
    """``value`` as type ``tp`` (int→float, list→tuple allowed), else ``ConfigError``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(tp):
            if option is type(None) and value is None:
                return None
            try:
                return coerce(value, option, where)
            except ConfigError:
                continue
        raise ConfigError(f"{where}: {value!r} is not {describe(tp)}")
    if origin in (tuple, list):
        args = typing.get_args(tp)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: {value!r} is not {describe(tp)}")
        item_type = args[0] if args else Any
        items = [coerce(v, item_type, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: {value!r} is not a table")
        return dict(value)
    if origin is typing.Literal:
        if value not in typing.get_args(tp):
            raise ConfigError(f"{where}: {value!r} is not one of {', '.join(map(repr, typing.get_args(tp)))}")
        return value
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp) and isinstance(tp, type) and not isinstance(value, tp):  # [nodes.web.limits]
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: {value!r} is not a table")
        return from_mapping(tp, value, where)
    if tp is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if tp in (int, float) and isinstance(value, bool):
        raise ConfigError(f"{where}: {value!r} is not {describe(tp)}")
    if isinstance(tp, type) and isinstance(value, tp):
        return value
    raise ConfigError(f"{where}: {value!r} is not {describe(tp)}")


def describe(tp: Any) -> str:
    """A type as a reader of a configuration file would say it."""
    names = {str: "a string", int: "an integer", float: "a number", bool: "true or false", dict: "a table"}
    origin = typing.get_origin(tp)
    if tp in names or origin is dict:
        return names[dict if origin is dict else tp]
    if origin in (tuple, list):
        args = [a for a in typing.get_args(tp) if a is not Ellipsis]
        return f"a list of {_plural(args[0])}" if args else "a list"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a) for a in typing.get_args(tp) if a is not type(None))
    return getattr(tp, "__name__", str(tp))


def _plural(tp: Any) -> str:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return " or ".join(_plural(a) for a in typing.get_args(tp) if a is not type(None))
    plurals = {str: "strings", int: "integers", float: "numbers", bool: "booleans", dict: "tables"}
    return plurals.get(dict if typing.get_origin(tp) is dict else tp, describe(tp))
