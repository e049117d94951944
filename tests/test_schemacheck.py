"""The compiled schema checks (bus/schemacheck.py) agree with jsonschema, and the gate asks jsonschema
only for the reason of a message that does not fit."""

from __future__ import annotations

import time
from typing import Any

import jsonschema
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sonibus import schemas
from sonibus.bus import codec, keys, messages
from sonibus.bus.schemacheck import compile_schema, fits
from sonibus.bus.stats import Counters, Report

CHECKED = ("node_stats", "robot_info", "derived_info")  # the schemas the gate checks with fits()

scalars = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.integers(), st.sampled_from([0.0, 1.0, -1.0, 0.5]),
                    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=4))
json_values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                            st.dictionaries(st.text(max_size=3), inner, max_size=3)),
                           max_leaves=8)


_made: dict[tuple[int, int, str], st.SearchStrategy[Any]] = {}


def _once(kind: str, schema: Any, depth: int, make: Any) -> st.SearchStrategy[Any]:
    """Each strategy made once (drawing builds none anew: hypothesis's regexes are slow to make)."""
    key = (id(schema), depth, kind)
    if key not in _made:
        _made[key] = make()
    return _made[key]


def near(schema: Any, depth: int = 0) -> st.SearchStrategy[Any]:
    """Values that mostly fit ``schema``, now and then a part something else (a bound crossed, a field
    missing or of another type, a key too many): what tells two checks apart is at the edges."""
    if not isinstance(schema, dict) or depth > 6:
        return json_values
    # deeper parts are more: each less often wrong, and a message fits now and then (3, not 0: hypothesis draws
    # the ends of a range more often than the rest)
    odds = 8 * (depth + 1) ** 2
    wrong = _once("wrong", schema, depth, lambda: _wrong(schema, depth))
    fitting = _once("fitting", schema, depth, lambda: _fitting(schema, depth))
    return _once("near", schema, depth, lambda: st.integers(0, odds).flatmap(lambda i: wrong if i == 3 else fitting))


def _fitting(schema: dict[str, Any], depth: int) -> st.SearchStrategy[Any]:
    fitting: list[st.SearchStrategy[Any]] = []
    if "enum" in schema:
        return st.sampled_from(schema["enum"])
    for sub in schema.get("anyOf", []) + schema.get("oneOf", []):
        fitting.append(near(sub, depth + 1))
    types = schema.get("type", [])
    for kind in [types] if isinstance(types, str) else types:
        if kind == "object":
            fitting.append(_object(schema, depth))
        elif kind == "array":
            items = near(schema.get("items", True), depth + 1)
            least, most = schema.get("minItems", 0), min(schema.get("maxItems", 3), 3)
            fitting.append(st.lists(items, min_size=least, max_size=most))
        elif kind in ("number", "integer"):
            low = schema.get("minimum", schema.get("exclusiveMinimum", -5))
            high = schema.get("maximum", schema.get("exclusiveMaximum", low + 10))
            inside = [low + 1, float(low + 1), high - 1] + ([] if kind == "integer" else [(low + high) / 2])
            if "exclusiveMinimum" not in schema:
                inside.append(low)
            if "exclusiveMaximum" not in schema:
                inside.append(high)
            fitting.append(st.sampled_from(inside))
        elif kind == "string":
            shortest, longest = schema.get("minLength", 0), schema.get("maxLength", 12)
            if "pattern" in schema:
                fitting.append(_matching(schema["pattern"], shortest, longest))
            else:
                fitting.append(st.text(alphabet="aZ_1-. ", min_size=schema.get("minLength", 0),
                                       max_size=min(schema.get("maxLength", 6), 6)))
        elif kind == "boolean":
            fitting.append(st.booleans())
    return st.one_of(*fitting) if fitting else json_values


def _matching(pattern: str, shortest: int, longest: int) -> st.SearchStrategy[str]:
    return st.from_regex(pattern).filter(lambda s: shortest <= len(s) <= longest)


def _wrong(schema: dict[str, Any], depth: int) -> st.SearchStrategy[Any]:
    edges = [schema[k] + d for k in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum") if k in schema
             for d in (-1, -0.5, 0, 0.5, 1)]
    sizes = [schema[k] + d for k in ("minLength", "maxLength") if k in schema for d in (-1, 0, 1) if schema[k] + d >= 0]
    wrong = [json_values, st.sampled_from([True, False, None, 1, 1.0, 2.5, -1, "", "x", "A", [], {}])]
    if edges:
        wrong.append(st.sampled_from(edges))
    if sizes:
        wrong.append(st.sampled_from(sizes).map(lambda n: "a" * n))
    if "pattern" in schema:
        wrong.append(st.sampled_from(["", "A", "a\n", "1a", " a", "a b"]))
    if schema.get("type") == "object" or "properties" in schema:
        wrong.append(_object(schema, depth, wrong=True))
    return st.one_of(*wrong)


def _object(schema: dict[str, Any], depth: int, wrong: bool = False) -> st.SearchStrategy[dict[str, Any]]:
    properties = schema.get("properties", {})
    rest = schema.get("additionalProperties", True)
    extra_value = near(rest, depth + 1) if isinstance(rest, dict) else json_values
    pattern = schema.get("propertyNames", {}).get("pattern")
    names = st.from_regex(pattern).filter(lambda s: len(s) < 12) if pattern else st.text(alphabet="abz_9", min_size=1,
                                                                                           max_size=4)
    most = min(schema.get("maxProperties", 4), 4)

    @st.composite
    def build(draw: Any) -> dict[str, Any]:
        value: dict[str, Any] = {}
        for name in properties:
            if name in schema.get("required", []) or draw(st.booleans()):
                value[name] = draw(near(properties[name], depth + 1))
        if rest is not False and not properties:
            for _ in range(draw(st.integers(schema.get("minProperties", 0), most))):
                value[draw(names)] = draw(extra_value)
        for name in schema.get("required", []):
            value.setdefault(name, draw(extra_value))
        for name, needed in schema.get("dependentRequired", {}).items():
            if name in value:
                for other in needed:
                    value.setdefault(other, draw(near(properties.get(other, True), depth + 1)))
        if wrong:  # one field too many, or one required missing
            if value and draw(st.booleans()):
                del value[draw(st.sampled_from(sorted(value)))]
            else:
                value[draw(st.one_of(names, st.text(max_size=3)))] = draw(json_values)
        return value
    return build()


@pytest.mark.parametrize("name", CHECKED)
def test_compiled_check_agrees_with_jsonschema(name: str) -> None:
    """For messages near each schema, fitting or not by a hair, the compiled check says what
    jsonschema says."""
    schema = schemas.load(name)
    compiled, validator = compile_schema(schema), jsonschema.Draft202012Validator(schema)
    seen = {True: 0, False: 0}

    @settings(max_examples=50, deadline=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
    @given(near(schema))
    def agree(message: Any) -> None:
        expected = validator.is_valid(message)
        seen[expected] += 1
        assert compiled(message) is expected, (message, next(validator.iter_errors(message), None))

    agree()
    assert seen[True] >= 3 and seen[False] >= 3, seen  # (both sides of the edge were tried: 8 to 42 of 50 each)


def test_integral_float_is_an_integer_and_a_bool_no_number() -> None:
    """jsonschema's meaning of a type, kept: 3.0 is an integer, True is no number, a pattern is searched."""
    check = compile_schema({"type": "object", "properties": {"n": {"type": "integer"}, "x": {"type": "number"},
                                                             "s": {"pattern": "^a$"}}})
    assert check({"n": 3.0, "x": 1, "s": "a\n"})   # ($ matches before a final newline, as re.search's)
    assert not check({"x": True})
    assert not check({"n": 3.5})


def test_unknown_keyword_is_refused_when_compiled() -> None:
    with pytest.raises(ValueError, match="uniqueItems"):
        compile_schema({"type": "array", "uniqueItems": True})


def _stats() -> dict[str, Any]:
    report = Report(Counters(messages_stats_counters()))
    return report.next({"host": "h", "node": "n", "adapter": "web", "state": "running", "since": time.time(),
                        "restarts": 0}, {"files": 2, "per_target": {"a": 1.0}})


def messages_stats_counters() -> tuple[str, ...]:
    return ("received", "sent", "dropped", "stale", "bad", "errors", "written")


def test_gate_asks_jsonschema_only_why_a_message_does_not_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    """A node's stats that fit pass without jsonschema's walk (~435 µs each, once a second from every
    node to every node that lists them); one that does not is refused with jsonschema's reason."""
    walked = []
    validator = schemas.validator("node_stats")
    real = type(validator).iter_errors
    monkeypatch.setattr(type(validator), "iter_errors", lambda self, message: walked.append(1) or real(self, message))
    gate, key = messages.Gate(), keys.Key.parse(keys.node_stats("h", "n"))
    assert fits("node_stats")(_stats())
    for _ in range(3):
        gate.check(key, codec.encode(_stats()))
    assert walked == []
    bad = {**_stats(), "state": "asleep"}
    with pytest.raises(messages.BadMessage, match="not a valid node stats: state: 'asleep' is not one of"):
        gate.check(key, codec.encode(bad))
    assert walked == [1]
