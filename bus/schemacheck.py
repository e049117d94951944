"""A JSON Schema compiled to one Python predicate: whether a message fits, ~20× cheaper than jsonschema.

The gate checks every node's stats (``node_stats``, once a second from each node, taken by the
web node and ``sonibus health``) and every robot's info (``robot_info``, ``derived_info``, asked
every 2 s by OSCQuery) against their schemas; jsonschema walks a stats message in ~435 µs, a
node's process paying it for each node it lists. ``compile_schema`` turns a schema into nested
closures that say only *whether* a message fits; a message that does not is then checked by
jsonschema itself, so that the one-line reason it is refused with stays jsonschema's. The
predicate and jsonschema agree on every message (``tests/test_schemacheck.py``: a property
test against ``jsonschema.Draft202012Validator.is_valid`` on the same schemas).

    fits = compile_schema(schemas.load("node_stats"))
    fits({"t": 1.0, ...})  # True or False

Only the keywords our schemas use are compiled, with jsonschema's (Draft 2020-12) meaning:
an integral float is an ``integer``, ``bool`` is no ``number``, a ``pattern`` is searched
(``re.search``), each keyword applies only to the type it is about. A schema with any other
keyword is refused when compiled (``ValueError``): a new keyword in a schema must not be
ignored silently.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from functools import cache
from typing import Any

from .. import schemas

Check = Callable[[Any], bool]

IGNORED = frozenset({"$schema", "$id", "title", "description", "$comment", "examples", "default"})


def _is_number(value: Any) -> bool:
    return value.__class__ is int or value.__class__ is float  # (a bool's class is bool: no number)


def _is_integer(value: Any) -> bool:
    return value.__class__ is int or (value.__class__ is float and value.is_integer())


TYPES: dict[str, Check] = {
    "object": lambda v: v.__class__ is dict,
    "array": lambda v: v.__class__ is list,
    "string": lambda v: v.__class__ is str,
    "number": _is_number,
    "integer": _is_integer,
    "boolean": lambda v: v.__class__ is bool,
    "null": lambda v: v is None,
}


@cache
def fits(name: str) -> Check:
    """The predicate of schema ``name`` (``schemas.load``), compiled once a process."""
    return compile_schema(schemas.load(name))


def compile_schema(schema: dict[str, Any] | bool) -> Check:
    """The predicate of ``schema`` (a JSON value already checked JSON-like: ``messages.json_like``)."""
    if schema is True:
        return lambda value: True
    if schema is False:
        return lambda value: False
    unknown = set(schema) - IGNORED - KEYWORDS
    if unknown:
        raise ValueError(f"schema keyword(s) {', '.join(sorted(unknown))} not compiled (bus/schemacheck.py): "
                         "add them there, with their jsonschema meaning")
    checks = [KEYWORDS_BUILD[keyword](schema[keyword], schema) for keyword in ORDER if keyword in schema]
    checks = [check for check in checks if check is not None]
    if len(checks) == 1:
        return checks[0]
    return lambda value: all(check(value) for check in checks)


def _type(types: str | list[str], schema: dict[str, Any]) -> Check:
    if isinstance(types, str):
        return TYPES[types]
    tests = [TYPES[t] for t in types]
    return lambda value: any(test(value) for test in tests)


def _enum(values: list[Any], schema: dict[str, Any]) -> Check:
    if not all(isinstance(v, str) for v in values):
        raise ValueError("enum: only strings are compiled (jsonschema's equality of numbers and booleans differs)")
    allowed = frozenset(values)
    return lambda value: value.__class__ is str and value in allowed


def _const(const: Any, schema: dict[str, Any]) -> Check:
    if not isinstance(const, str):
        raise ValueError("const: only a string is compiled")
    return lambda value: value.__class__ is str and value == const


def _bound(test: Callable[[Any], bool]) -> Check:
    return lambda value: not _is_number(value) or test(value)


def _minimum(bound: float, schema: dict[str, Any]) -> Check:
    return _bound(lambda v: v >= bound)


def _maximum(bound: float, schema: dict[str, Any]) -> Check:
    return _bound(lambda v: v <= bound)


def _exclusive_minimum(bound: float, schema: dict[str, Any]) -> Check:
    return _bound(lambda v: v > bound)


def _exclusive_maximum(bound: float, schema: dict[str, Any]) -> Check:
    return _bound(lambda v: v < bound)


def _sized(cls: type, test: Callable[[int], bool]) -> Check:
    return lambda value: value.__class__ is not cls or test(len(value))


def _pattern(pattern: str, schema: dict[str, Any]) -> Check:
    search = re.compile(pattern).search
    return lambda value: value.__class__ is not str or search(value) is not None


def _required(names: list[str], schema: dict[str, Any]) -> Check:
    return lambda value: value.__class__ is not dict or all(name in value for name in names)


def _dependent_required(dependencies: dict[str, list[str]], schema: dict[str, Any]) -> Check:
    pairs = list(dependencies.items())
    return lambda value: value.__class__ is not dict or all(
        name not in value or all(other in value for other in needed) for name, needed in pairs)


def _properties(properties: dict[str, Any], schema: dict[str, Any]) -> Check:
    """``properties`` and ``additionalProperties`` together (a key is one or the other)."""
    known = {name: compile_schema(sub) for name, sub in properties.items()}
    rest = schema.get("additionalProperties", True)
    other = compile_schema(rest)
    anything = rest is True

    def check(value: Any) -> bool:
        if value.__class__ is not dict:
            return True
        for name, item in value.items():
            test = known.get(name)
            if test is None:
                if not anything and not other(item):
                    return False
            elif not test(item):
                return False
        return True
    return check


def _additional(rest: Any, schema: dict[str, Any]) -> Check | None:
    if "properties" in schema:
        return None  # (compiled with them)
    return _properties({}, schema)


def _property_names(names: Any, schema: dict[str, Any]) -> Check:
    test = compile_schema(names)
    return lambda value: value.__class__ is not dict or all(test(name) for name in value)


def _items(items: Any, schema: dict[str, Any]) -> Check:
    test = compile_schema(items)
    return lambda value: value.__class__ is not list or all(test(item) for item in value)


def _any_of(schemas: list[Any], schema: dict[str, Any]) -> Check:
    tests = [compile_schema(sub) for sub in schemas]
    return lambda value: any(test(value) for test in tests)


def _one_of(schemas: list[Any], schema: dict[str, Any]) -> Check:
    tests = [compile_schema(sub) for sub in schemas]
    return lambda value: sum(1 for test in tests if test(value)) == 1


def _all_of(schemas: list[Any], schema: dict[str, Any]) -> Check:
    tests = [compile_schema(sub) for sub in schemas]
    return lambda value: all(test(value) for test in tests)


KEYWORDS_BUILD: dict[str, Callable[[Any, dict[str, Any]], Check | None]] = {
    "type": _type, "enum": _enum, "const": _const,
    "minimum": _minimum, "maximum": _maximum, "exclusiveMinimum": _exclusive_minimum,
    "exclusiveMaximum": _exclusive_maximum,
    "minLength": lambda n, s: _sized(str, lambda size: size >= n),
    "maxLength": lambda n, s: _sized(str, lambda size: size <= n),
    "minItems": lambda n, s: _sized(list, lambda size: size >= n),
    "maxItems": lambda n, s: _sized(list, lambda size: size <= n),
    "minProperties": lambda n, s: _sized(dict, lambda size: size >= n),
    "maxProperties": lambda n, s: _sized(dict, lambda size: size <= n),
    "pattern": _pattern, "required": _required, "dependentRequired": _dependent_required,
    "properties": _properties, "additionalProperties": _additional, "propertyNames": _property_names,
    "items": _items, "anyOf": _any_of, "oneOf": _one_of, "allOf": _all_of,
}
KEYWORDS = frozenset(KEYWORDS_BUILD)
# cheap keywords first: a wrong type or a missing field is refused before a walk of the fields
ORDER = ("type", "enum", "const", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum", "minLength",
         "maxLength", "minItems", "maxItems", "minProperties", "maxProperties", "pattern", "required",
         "dependentRequired", "properties", "additionalProperties", "propertyNames", "items", "anyOf", "oneOf",
         "allOf")
