"""Forward kinematics against the test vectors computed from the robots' URDFs (robots.json)."""

from __future__ import annotations

import numpy as np
import pytest

from sonibus.adapters.features.kinematics import SIDES, fk_vectors, load_arms
from sonibus.bus import load_model

TOLERANCE_M = 0.001
VECTORS = [(model, name) for model in ("pepper", "nao") for name in fk_vectors(model)]


@pytest.mark.parametrize(("model", "name"), VECTORS, ids=[f"{m}-{n}" for m, n in VECTORS])
def test_fk_matches_every_urdf_test_vector_within_1_mm(model, name):
    vector = fk_vectors(model)[name]
    arms = load_arms(model)
    arm = SIDES.index(vector["chain"][0][0])
    last = vector["chain"][-1]
    upto = None if last.endswith("Hand") else arms.joints[arm].index(last)  # a wrist vector: that joint's origin
    angles = np.array([[vector.get("q", {}).get(j, 0.0) for j in joints] for joints in arms.joints])
    position = arms.points(angles, upto)[arm]
    assert np.abs(position - vector["pos"]).max() <= TOLERANCE_M, (position, vector["pos"])


def test_every_model_has_vectors_for_both_hands_and_wrists():
    for model in ("pepper", "nao"):
        chains = {tuple(v["chain"]) for v in fk_vectors(model).values()}
        assert {c[-1] for c in chains} == {"LHand", "RHand", "LWristYaw", "RWristYaw"}


def test_peppers_elbow_frame_is_pre_rotated():
    """Pepper's ElbowYaw origin is pitched −9° about y (robots.json ``origin_rpy_rad``); NAO's is not."""
    c, s = np.cos(-0.157079), np.sin(-0.157079)
    assert np.allclose(load_arms("pepper").rotations[:, 2], [[c, 0, s], [0, 1, 0], [-s, 0, c]])
    assert np.allclose(load_arms("nao").rotations, np.eye(3))


@pytest.mark.parametrize("model", ["pepper", "nao"])
def test_reach_box_holds_every_hand_within_the_joint_limits(model):
    arms, table = load_arms(model), load_model(model)
    limits = [[(table.joint(j).min, table.joint(j).max) for j in joints] for joints in arms.joints]
    low, high = arms.reach_boxes(limits)
    rng = np.random.default_rng(8)
    lows, highs = (np.array(limits)[..., i] for i in (0, 1))
    angles = rng.uniform(lows, highs, size=(20_000, *lows.shape))
    hands = arms.points(angles)
    assert (hands >= low).all() and (hands <= high).all()
    assert (high - low < 1.2).all()  # a bound, not the whole room


def test_hands_by_name_and_batches_agree():
    arms = load_arms("nao")
    angles = {"LShoulderPitch": 0.3, "RElbowRoll": 1.0, "RWristYaw": -0.5}
    one = arms.hands(angles)
    batch = arms.points(np.array([[[angles.get(j, 0.0) for j in joints] for joints in arms.joints]] * 3))
    assert batch.shape == (3, 2, 3) and np.allclose(batch, one)
