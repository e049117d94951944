"""A robot's features on frames that no robot should send: whatever comes in, what
goes out is finite and inside the ranges ``<robot>/info/derived`` declares, and
what was clamped or refused is counted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonibus.adapters.features import FeaturesConfig, catalog
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.table import describe
from sonibus.bus import keys, load_model

from .conftest import T0, model_info

PEPPER = load_model("pepper")
REST = {keys.joint("pepper", j): 0.0 for j in PEPPER.joint_names}
HEAD_MAX = PEPPER.joint("HeadYaw").max_velocity


def robot() -> tuple[RobotFeatures, dict[str, tuple[np.ndarray, np.ndarray]]]:
    described = describe("pepper", model_info("pepper"))
    ranges = catalog.bounds(catalog.derived(described, FeaturesConfig(), {}))
    return RobotFeatures(described, FeaturesConfig(), ranges), ranges


def outside(samples, ranges) -> list:
    """Samples not finite or outside their key's declared range."""
    wrong = []
    for key, message in samples:
        v = np.asarray(message["v"], dtype=float)
        low, high = ranges[key]
        if not (np.isfinite(v).all() and (v >= low).all() and (v <= high).all()):
            wrong.append((key, message["v"]))
    return wrong


POISON = {
    "1e5 everywhere": dict.fromkeys(REST, 1e5),
    "1e6 head": {**REST, "pepper/joints/HeadYaw": 1e6},
    "arms beyond their limits": {**REST, **{keys.joint("pepper", j): 3.0 for j in PEPPER.joint_names
                                            if j[1:] in ("ShoulderRoll", "ElbowRoll", "ShoulderPitch")}},
    "inf head": {**REST, "pepper/joints/HeadYaw": math.inf},
    "nan head": {**REST, "pepper/joints/HeadYaw": math.nan},
}


@pytest.mark.parametrize("name", list(POISON))
def test_whatever_comes_in_what_goes_out_is_inside_the_declared_ranges(name):
    features, ranges = robot()
    out = []
    for k in range(40):
        frame = POISON[name] if k in (15, 16) else {**REST, "pepper/joints/HeadYaw": 0.5 * math.sin(k / 10)}
        out.append(features.step(T0 + k / 100, k, frame))
    samples = [s for o in out for s in o.samples]
    assert not outside(samples, ranges)
    assert len({k for k, _ in samples}) == len(ranges)  # every key was published
    head = [o for o in out[18:] if any(k == "pepper/derived/velocity/HeadYaw" for k, _ in o.samples)]
    assert len(head) >= 40 - 18 - 1, "HeadYaw's velocity must be back within a frame or two"
    if name == "arms beyond their limits":
        assert sum(o.clamped for o in out) > 0
    elif "nan" not in name:
        assert sum(o.rejected for o in out) > 0 and out[15].refused


def test_a_joint_a_bit_faster_than_its_max_is_clamped_to_it_and_counted():
    """1.5 × the max velocity: faster than the robot can go, not a glitch: clamped, not refused."""
    features, ranges = robot()
    outs = [features.step(T0 + k / 100, k, {**REST, "pepper/joints/HeadYaw": 1.5 * HEAD_MAX * k / 100})
            for k in range(30)]
    velocities = [m["v"] for o in outs for key, m in o.samples if key == "pepper/derived/velocity/HeadYaw"]
    declared = ranges["pepper/derived/velocity/HeadYaw"][1]
    assert velocities[-1] == declared and max(velocities) == declared
    assert sum(o.clamped for o in outs) > 0 and sum(o.rejected for o in outs) == 0
