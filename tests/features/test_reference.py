"""The per-frame features in plain floats against the numpy computation they replaced
(``reference.py``, issue 35), frame by frame on random frames: the same names in the same
order, values within 1e-12, the same events at the same frames, the same counts of what
was missing, refused, clamped or dropped. The frames move every joint and add what robots
and networks send now and then: joints left out, NaN, ±inf, glitches, ints and bools, a
string, time standing still or going back, gaps, jumps faster than a joint can go."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from sonibus.adapters.features import FeaturesConfig, catalog
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.config import DEFAULT
from sonibus.adapters.features.kinematics import chains
from sonibus.adapters.features.table import describe

from .conftest import T0, model_info
from .reference import ReferenceFeatures

TOLERANCE = 1e-12  # of a value's size (or absolute, under 1)


def arm_info() -> dict:
    """tests/ros2's URDF arm: chains with axes off x, y and z, and a prismatic joint."""
    from sonibus.adapters.ros2.description import describe as describe_urdf
    from sonibus.adapters.ros2.urdf import parse

    from ..ros2.conftest import ARM_URDF, CHAINS

    arm = describe_urdf(parse(ARM_URDF.read_text(), str(ARM_URDF)), CHAINS)
    return {"model": arm.model.name, "joints": [j.to_info() for j in arm.model.joints], "kinematics": arm.kinematics}


def frames(info: dict, robot: str, count: int, seed: int):
    """``count`` frames ``(t, seq, values)``: every joint swinging through most of its range
    in bursts (motion onsets and offsets), with the oddities of the module's docstring."""
    rng = np.random.default_rng(seed)
    joints = info["joints"]
    low = np.array([j.get("min", -1.0) if j.get("min") is not None else -1.0 for j in joints])
    high = np.array([j.get("max", 1.0) if j.get("max") is not None else 1.0 for j in joints])
    middle, half = (low + high) / 2, (high - low) / 2
    phase, speed = rng.uniform(0, 2 * np.pi, len(joints)), rng.uniform(0.5, 3.0, len(joints))
    t = T0
    for k in range(count):
        t += float(rng.choice([0.01, 0.02, 0.013, 0.0, -0.03, 0.7], p=[0.8, 0.08, 0.06, 0.02, 0.02, 0.02]))
        burst = 1.0 if (k // 60) % 2 == 0 else 0.02  # moving, then nearly still
        q = middle + 0.8 * half * np.sin(burst * speed * (t - T0) + phase)
        values: dict = {f"{robot}/joints/{j['name']}": float(x) for j, x in zip(joints, q, strict=True)}
        names = list(values)
        for _ in range(rng.poisson(0.3)):
            key = names[rng.integers(len(names))]
            x = float(q[names.index(key)])
            values[key] = [math.nan, math.inf, -math.inf, 1e5, x + 0.3, x + 3.0, True, 0, "up", None][
                rng.choice(10, p=[0.2, 0.05, 0.05, 0.1, 0.2, 0.1, 0.05, 0.1, 0.1, 0.05])]
            if rng.random() < 0.2:
                del values[key]
        yield t, k, values


def close(a, b) -> bool:
    if isinstance(b, list):
        return isinstance(a, list) and len(a) == len(b) and all(close(x, y) for x, y in zip(a, b, strict=True))
    return abs(a - b) <= TOLERANCE * max(1.0, abs(b))


def same_events(ours, theirs) -> bool:
    if len(ours) != len(theirs):
        return False
    for (key, event), (their_key, their_event) in zip(ours, theirs, strict=True):
        segment, their_segment = event.get("segment"), their_event.get("segment")
        plain = {k: v for k, v in event.items() if k != "segment"}
        if key != their_key or plain != {k: v for k, v in their_event.items() if k != "segment"}:
            return False
        if (segment is None) != (their_segment is None) or (segment is not None and (
                segment.keys() != their_segment.keys() or not all(close(segment[k], their_segment[k])
                                                                   for k in segment))):
            return False
    return True


ROBOTS = {"pepper": lambda: model_info("pepper"), "nao": lambda: model_info("nao"), "arm": arm_info}


@cache
def robot_of(name: str):
    """The robot ``name`` as a processor sees it, and its info (one for both tests: its arms' reach
    boxes are worked out once)."""
    info = ROBOTS[name]()
    return describe(name, info), info


@pytest.mark.parametrize("features", [DEFAULT, (*DEFAULT, "expressive")], ids=["default", "expressive"])
@pytest.mark.parametrize("robot", list(ROBOTS))
def test_the_plain_float_step_gives_what_the_numpy_step_gave(robot, features):
    described, info = robot_of(robot)
    assert described.arms is not None, described.unavailable
    config = FeaturesConfig(features=features)
    ranges = catalog.bounds(catalog.derived(described, config, {}))
    ours, theirs = RobotFeatures(described, config, ranges), ReferenceFeatures(described, config, ranges)
    counts = dict.fromkeys(("events", "rejected", "clamped", "dropped", "values"), 0)
    for t, seq, values in frames(info, robot, 400 if "expressive" in features else 600, seed=len(robot)):
        got, expected = ours.step(t, seq, values), theirs.step(t, seq, values)
        samples, reference = got.samples, expected.samples
        assert [k for k, _ in samples] == [k for k, _ in reference], seq
        for (key, message), (_, wanted) in zip(samples, reference, strict=True):
            assert (message["t"], message["seq"]) == (wanted["t"], wanted["seq"])
            assert type(message["v"]) is type(wanted["v"]) and close(message["v"], wanted["v"]), (seq, key)
        assert same_events(got.events, expected.events), (seq, got.events, expected.events)
        assert (got.missing, got.nan, got.rejected, got.refused, got.clamped, got.dropped) == (
            expected.missing, expected.nan, expected.rejected, expected.refused, expected.clamped, expected.dropped)
        counts["events"] += len(got.events)
        counts["values"] += len(samples)
        for name in ("rejected", "clamped", "dropped"):
            counts[name] += getattr(got, name)
    # the frames did reach every path: motion events, glitches refused, values clamped
    assert counts["events"] >= 4 and counts["rejected"] >= 10 and counts["clamped"] >= 1, counts
    assert counts["values"] >= 10 * 400, counts


def random_arms():
    """Two chains of random links: axes anywhere (and along −x, −y, −z), origins turned any way, a
    prismatic joint, chains of different lengths (one padded)."""
    rng = np.random.default_rng(5)
    axes = [rng.normal(size=3), [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -2.0], rng.normal(size=3)]

    def link(i: int, axis) -> dict:
        return {"joint": f"J{i}", "origin_xyz_m": rng.uniform(-0.2, 0.2, 3).tolist(),
                "origin_rpy_rad": rng.uniform(-1.0, 1.0, 3).tolist(), "axis": list(axis),
                "type": "prismatic" if i == 3 else "revolute"}

    long = [link(i, axis) for i, axis in enumerate(axes)] + [link(9, [1.0, 0.0, 0.0])]
    short = [link(10 + i, axis) for i, axis in enumerate(axes[:2])] + [link(19, [1.0, 0.0, 0.0])]
    return chains(("long", "short"), [long, short])


@pytest.mark.parametrize("robot", [*ROBOTS, "random"])
def test_hand_points_in_floats_are_the_matrix_products(robot):
    arms = random_arms() if robot == "random" else robot_of(robot)[0].arms
    assert arms is not None
    rng = np.random.default_rng(3)
    q = rng.uniform(-3.0, 3.0, (300, len(arms.sides), arms.axes.shape[1]))
    theirs = arms.points(q).reshape(len(q), -1)
    for angles, expected in zip(q, theirs, strict=True):
        assert np.abs(np.array(arms.hand_points(angles.tolist())) - expected).max() <= 1e-12
