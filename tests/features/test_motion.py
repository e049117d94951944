"""Quantity of motion and motion onsets/offsets on synthetic data: hysteresis,
minimum duration, one onset and one offset per gesture, none from sensor noise."""

from __future__ import annotations

import numpy as np
import pytest

from sonibus import schemas
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.config import FeaturesConfig
from sonibus.adapters.features.motion import OnsetDetector, weights
from sonibus.adapters.features.table import describe
from sonibus.bus import load_model

from .conftest import T0, gesture, model_info

PEPPER = load_model("pepper")
NOISE_RAD = 0.001  # σ of the gaussian sensor noise added to every joint (0.06°)


def test_weights_count_radians_not_hands():
    w = weights(["rad", "rad", "fraction"], ["HeadYaw", "RElbowRoll", "RHand"], {"RElbowRoll": 2.0})
    assert w.tolist() == [1.0, 2.0, 0.0]


def feed(detector: OnsetDetector, values: list[float], rate_hz: float = 100.0) -> list[tuple[float, str]]:
    out = []
    for k, value in enumerate(values):
        change = detector.update(k / rate_hz, value)
        if change:
            out.append((round(k / rate_hz, 2), change))
    return out


def test_between_the_thresholds_nothing_changes():
    """Hysteresis: 0.35 is below onset (0.5) and above offset (0.2) — whatever the state, it stays."""
    still = OnsetDetector(0.5, 0.2, 0.05)
    assert feed(still, [0.35] * 100) == []
    moving = OnsetDetector(0.5, 0.2, 0.05)
    assert feed(moving, [1.0] * 10 + [0.35] * 100) == [(0.05, "onset")]


def test_a_state_must_last_the_minimum_duration():
    d = OnsetDetector(0.5, 0.2, 0.08)
    twitch = [0.0] * 10 + [2.0] * 5 + [0.0] * 10           # 50 ms above onset: no motion
    assert feed(d, twitch) == []
    motion = [2.0] * 30 + [0.0] * 5 + [2.0] * 30 + [0.0] * 30  # a 50 ms pause inside: one motion
    assert feed(d, twitch + motion) == [(0.33, "onset"), (0.98, "offset")]


def frames(rate_hz: float, seconds: float, seed: int, drop: float = 0.0,
           moves: dict[str, tuple[float, float, float]] | None = None):
    """StandInit plus gaussian noise, with ``moves`` (joint → start s, duration s, amplitude rad) added."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    t = t[rng.random(len(t)) >= drop]
    pose = PEPPER.posture("StandInit")
    names = PEPPER.joint_names
    q = np.array([[pose.get(j, 0.0) for j in names]] * len(t)) + rng.normal(0.0, NOISE_RAD, (len(t), len(names)))
    for joint, (start, duration, amplitude) in (moves or {}).items():
        q[:, names.index(joint)] += gesture(t, start, duration, amplitude)
    for k, ti in enumerate(t):
        yield T0 + ti, k, {f"pepper/joints/{j}": float(v) for j, v in zip(names, q[k], strict=True)}


def run(stream) -> tuple[list[dict], dict[str, float]]:
    features = RobotFeatures(describe("pepper", model_info("pepper")), FeaturesConfig())
    events, peak = [], {}
    for t, seq, values in stream:
        out = features.step(t, seq, values)
        events += [message for _, message in out.events]
        for key, message in out.samples:
            if "/qom/" in key:
                peak[key.rsplit("/", 1)[1]] = max(peak.get(key.rsplit("/", 1)[1], 0.0), message["v"])
    for message in events:
        schemas.validate("event", message)
    return events, peak


@pytest.mark.parametrize("rate_hz", [100.0, 50.0])
def test_sensor_noise_alone_makes_no_event(rate_hz):
    events, peak = run(frames(rate_hz, 30.0, seed=3))
    assert events == []
    assert 0.05 < peak["RArm"] < FeaturesConfig().onset  # the noise is seen, below the threshold


ARM_GESTURES = {"RShoulderPitch": (2.0, 1.5, -1.0), "RElbowRoll": (2.1, 1.2, 0.8),
                "LShoulderPitch": (6.0, 2.0, -0.6), "LShoulderRoll": (6.0, 2.0, 0.4)}


@pytest.mark.parametrize("drop", [0.0, 0.2])
def test_one_onset_and_one_offset_per_gesture_in_noise(drop):
    events, _ = run(frames(100.0, 10.0, seed=4, drop=drop, moves=ARM_GESTURES))
    found = [(e["chain"], e["state"], round(e["t"] - T0, 1)) for e in events]
    assert [(c, s) for c, s, _ in found] == [("RArm", "onset"), ("RArm", "offset"), ("LArm", "onset"),
                                             ("LArm", "offset")], found
    (_, _, r_on), (_, _, r_off), (_, _, l_on), (_, _, l_off) = found
    assert 2.0 <= r_on <= 2.3 and 3.3 <= r_off <= 3.7      # the right arm moves from 2 s to 3.5 s
    assert 6.0 <= l_on <= 6.4 and 7.6 <= l_off <= 8.2      # the left arm from 6 s to 8 s
