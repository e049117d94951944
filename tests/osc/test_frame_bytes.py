"""Issue 27: a robot's frames go out from datagrams worked out once per target and joint
list (``profiles.FrameBytes``), byte for byte what the general path, one joint at a time
through ``sample`` and ``frame``, sends — for every profile and option."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.adapters.osc.config import Target
from sonibus.adapters.osc.encode import NTP_OFFSET, EncodeError
from sonibus.adapters.osc.profiles import PROFILES
from sonibus.bus.keys import Key
from sonibus.bus.messages import MAX_VALUE

settings.register_profile("osc", deadline=None)
settings.load_profile("osc")

REFUSED = (struct.error, OverflowError, ValueError)  # what the sink's plan may raise: it then takes the general path
NAMES = st.lists(st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True), min_size=1, max_size=20, unique=True)
VALUE = st.one_of(st.floats(-MAX_VALUE, MAX_VALUE), st.integers(-10, 10).map(float),  # what passes the gate
                  st.floats(allow_nan=False).filter(lambda v: abs(v) > 3.5e38))      # and what OSC cannot carry
TEMPLATES = ["/{robot}/joints/{joint}", "/{key}", "/x/{name}/{section}/{robot}", "/ü/{joint}"]


@st.composite
def targets(draw: st.DrawFn) -> Target:
    if draw(st.booleans()):
        return Target(to="127.0.0.1:9", profile="pepperosc")
    return Target(to="127.0.0.1:9", address=draw(st.sampled_from(TEMPLATES)),
                  extra=tuple(draw(st.lists(st.sampled_from(["t", "seq"]), max_size=3))),
                  bundle=draw(st.booleans()), latency_ms=draw(st.floats(0, 1e4)))


def general(target: Target, sources: list[Key], values: list[float], t: float, seq: int,
            interval: float) -> list[bytes] | None:
    """What the general path sends of a frame (None: it leaves something out, as unencodable)."""
    profile = PROFILES[target.profile](target)
    try:
        if target.framed:
            samples = [(s, (v,)) for s, v in zip(sources, values, strict=True)]
            datagrams, dropped = profile.frame("pepper", t, seq, samples, interval)
            return None if dropped else datagrams
        return [profile.sample(s, (v,), t, seq) for s, v in zip(sources, values, strict=True)]
    except EncodeError:
        return None


@given(targets(), NAMES, st.data(), st.floats(0, 2**32 - NTP_OFFSET - 1), st.integers(0, 2**63 - 1),
       st.floats(0, 1e3))
@settings(max_examples=300)
def test_a_frame_s_precomputed_bytes_are_the_general_path_s(target, names, data, t, seq, interval):
    values = data.draw(st.lists(VALUE, min_size=len(names), max_size=len(names)))
    sources = [Key.parse(f"pepper/joints/{name}") for name in names]
    compiled = PROFILES[target.profile](target).compile(sources)
    assert compiled is not None
    expected = general(target, sources, values, t, seq, interval)
    if expected is None:  # a value OSC cannot carry: the sink's plan gives up, the general path leaves it out
        with pytest.raises(REFUSED):
            compiled.render(t, seq, values, interval)
    else:
        assert compiled.render(t, seq, values, interval) == expected
