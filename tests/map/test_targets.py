"""A map's robot command (``target``): refused at load when it cannot be sent, with file,
line and key; and whatever its source sends (10,000 random values, NaN and infinities
among them), every command its chain builds passes the owner's own validation: within
the joint's limits, finite, at the map's speed."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sonibus.adapters.map.chain import Chain
from sonibus.adapters.map.config import parse_map
from sonibus.bus import commands
from sonibus.bus.robot import load_model

from .test_config import refused

PEPPER = load_model("pepper")
LIMITS = {j.name: (j.min, j.max) for j in PEPPER.joints}


@pytest.mark.parametrize("extra, fragment", [
    ('target = {robot = "pepper", command = "joints/set"}\n', "joints/set needs joint = \"...\""),
    ('target = {robot = "pepper", command = "dance", joint = "HeadPitch"}\n',
     "command 'dance' is not one a map sends — commands: joints/set, posture, behavior/run, say"),
    ('target = {robot = "pepper", command = "posture", name = "Crouch"}\n',
     "posture is sent when the map's threshold turns on: give the map threshold = [ON, OFF]"),
    ('target = {robot = "pepper", command = "joints/set", joint = "HeadPitch", speed = 1.5}\n',
     "speed 1.5 must be more than 0 and at most 1"),
    ('target = {robot = "pepper", command = "joints/set", joint = "HeadPitch", hz = 1000}\n',
     "hz 1000 must be more than 0 and at most 100"),
    ('target = {robot = "pepper", command = "say", text = "hi", speed = 0.5}\nthreshold = [1000, 500]\n',
     "speed is for joints/set and posture, not say"),
    ('target = {robot = "pep/per", command = "say", text = "hi"}\nthreshold = [1000, 500]\n',
     "robot name 'pep/per' must be non-empty"),
    ('target = {robot = "pepper", command = "joints/set", joint = "HeadPitch", angle = 1}\n',
     "unknown key 'angle' — keys: robot, command, joint, name, text, speed, hz"),
])
def test_a_target_that_cannot_be_sent_is_refused_with_file_line_and_key(extra, fragment):
    message = refused(extra)
    assert message.startswith("shows/museum.toml [nodes.sound] line 11: key 'maps.cutoff.target': "), message
    assert fragment in message, message


@st.composite
def joint_maps(draw):
    """A map driving one of Pepper's joints, its ``to`` within the joint's limits, with a
    random curve and random steps after it."""
    joint = draw(st.sampled_from(sorted(LIMITS)))
    low, high = LIMITS[joint]
    ends = draw(st.lists(st.floats(low, high), min_size=2, max_size=2, unique=True))
    table = {"source": "pepper/derived/onset/speaker", "to": ends,
             "curve": draw(st.sampled_from(["linear", "exp", "log", "s"])),
             "invert": draw(st.booleans()),
             "target": {"robot": "pepper", "command": "joints/set", "joint": joint,
                        "speed": draw(st.floats(0.01, 1.0))}}
    if table["curve"] in ("exp", "log"):
        table["base"] = draw(st.sampled_from([0.1, 2.0, 10.0, 1000.0]))
    smoothing = draw(st.sampled_from(["none", "smooth_ms", "one_euro", "rate_limit"]))
    if smoothing == "smooth_ms":
        table["smooth_ms"] = draw(st.floats(1.0, 500.0))
    elif smoothing == "one_euro":
        table["one_euro"] = {"min_cutoff": draw(st.floats(0.1, 10.0)), "beta": draw(st.floats(0.0, 5.0))}
    elif smoothing == "rate_limit":
        table["rate_limit"] = draw(st.floats(0.01, 10.0))
    return parse_map("follow", table)


SOURCE_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-2.0, 2.0),
                          st.sampled_from([0.0, 1.0, -1e308, 1e308, math.nan, math.inf, -math.inf, 5e-324]))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(spec=joint_maps(), values=st.lists(SOURCE_VALUES, min_size=100, max_size=100),
       span=st.sampled_from([(0.0, 1.0), (-100.0, 0.0), (-1e6, 1e6)]))
def test_random_source_values_never_make_a_command_outside_the_limits_or_a_nan(spec, values, span):
    # 100 maps × 100 values: 10,000 source values through the chain and the command builder
    chain, target = Chain(spec), spec.target
    low, high = LIMITS[target.joint]
    for i, value in enumerate(values):
        t = 1000.0 + i * 0.01
        if not chain.feed("x", value, span, t):
            continue
        out = chain.compute(t)
        if out is None or out.value is None:
            continue
        assert math.isfinite(out.value), value  # (the map's own output, published beside the command)
        request = target.request(out.value)
        command = commands.validate("joints/set", request, PEPPER)  # the owner's check: raises if refused
        angle = command.args["angles"][0]
        assert math.isfinite(angle) and low <= angle <= high, (value, angle)
        assert command.args["speed"] == target.speed <= 1.0
