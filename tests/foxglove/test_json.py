"""A channel's payload (``wire.to_json``) is ``json``'s compact, strict JSON byte for byte,
whatever a robot sends: samples are written without the encoder (issue 35), every other
message by it, and what JSON cannot carry raises as ``json`` raises."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.adapters.foxglove import wire
from sonibus.adapters.recorder import channels


def reference(message: Any) -> bytes:
    return json.dumps(message, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode()


def outcome(encode: Any, message: Any) -> tuple[str, Any]:
    try:
        return "ok", encode(message)
    except (ValueError, TypeError) as exc:
        return type(exc).__name__, str(exc)


numbers = st.one_of(st.floats(), st.integers(), st.booleans(), st.floats(width=32),
                    st.sampled_from([0.0, -0.0, 1e-05, 1e16, 1e22, 5e-324, 1.7976931348623157e308, 0.1 + 0.2]))
values = st.one_of(numbers, st.none(), st.text(max_size=4), st.lists(numbers, max_size=3))
samples = st.fixed_dictionaries({"t": numbers, "seq": numbers, "v": values})
reordered = st.permutations(["t", "seq", "v"]).flatmap(
    lambda order: st.tuples(*[values for _ in order]).map(lambda vs: dict(zip(order, vs, strict=True))))
others = st.dictionaries(st.text(max_size=5), values, max_size=4)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.one_of(samples, reordered, others), min_size=1, max_size=6))
def test_every_message_is_json_s_bytes_or_its_error(messages):
    for message in messages:
        assert outcome(wire.to_json, message) == outcome(reference, message), message
        assert outcome(channels.to_json, message) == outcome(reference, message), message


@settings(max_examples=100, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False), st.integers(min_value=0, max_value=2**40),
       st.lists(st.floats(), min_size=1, max_size=30))
def test_a_frame_s_samples_sharing_t_and_seq_are_json_s(t, seq, vs):
    """The samples of a frame share their ``t`` and ``seq`` objects (written once for them):
    each still gets its own ``v``, and the next frame (a new ``t``, the same ``seq`` object, or
    the other way round) its own."""
    for time_, number in ((t, seq), (t, seq + 1), (t + 1.0, seq), (t, seq)):
        for v in vs:
            message = {"t": time_, "seq": number, "v": v}
            assert outcome(wire.to_json, message) == outcome(reference, message)


def test_what_json_cannot_carry_raises_as_json_does():
    with pytest.raises(ValueError, match="Out of range float"):
        wire.to_json({"t": 1.5, "seq": 1, "v": math.inf})
    with pytest.raises(ValueError, match="Out of range float"):
        wire.to_json({"t": math.nan, "seq": 1, "v": 0.5})
    with pytest.raises(TypeError, match="Object of type bytes is not JSON serializable"):
        wire.to_json({"t": 1.5, "seq": 1, "v": b"x"})
