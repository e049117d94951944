"""The conversions to Foxglove's messages: transforms that compose to the forward
kinematics of the features processor and robots.json's URDF test vectors, and
log lines that say what happened, all valid against Foxglove's published schemas."""

from __future__ import annotations

from typing import Any

import jsonschema
import numpy as np
import pytest

from sonibus.adapters.features.kinematics import fk_vectors, load_arms
from sonibus.adapters.foxglove.convert import ArmFrames, arm_frames, log_message
from sonibus.schemas import foxglove as schemas


def matrix(q: dict[str, float]) -> np.ndarray:
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def origins(message: dict[str, Any], root: str) -> dict[str, np.ndarray]:
    """Every frame's origin in ``root``, composed from the transforms as Foxglove does
    (translation, then rotation, each in its parent's frame)."""
    poses = {root: (np.zeros(3), np.eye(3))}
    pending = list(message["transforms"])
    while pending:
        ready = [tf for tf in pending if tf["parent_frame_id"] in poses]
        assert ready, f"transforms whose parents are not reachable from {root}: {pending}"
        for tf in ready:
            position, rotation = poses[tf["parent_frame_id"]]
            offset = np.array([tf["translation"][c] for c in "xyz"])
            poses[tf["child_frame_id"]] = (position + rotation @ offset, rotation @ matrix(tf["rotation"]))
            pending.remove(tf)
    return {frame: pose[0] for frame, pose in poses.items()}


def frame_of(angles: dict[str, float], t: float = 1763900000.5) -> dict[str, Any]:
    return {"t": t, "seq": 7, "names": list(angles), "v": list(angles.values())}


@pytest.mark.parametrize("model", ["pepper", "nao"])
def test_the_hand_frames_compose_to_the_kinematics_hands(model):
    arms, frames = load_arms(model), ArmFrames.of(model)
    rng = np.random.default_rng(19)
    joints = [j for arm in arms.joints for j in arm]
    for _ in range(20):
        angles = {j: float(a) for j, a in zip(joints, rng.uniform(-2.0, 2.0, len(joints)), strict=True)}
        message = frames.transforms("r2", frame_of(angles))
        jsonschema.validate(message, schemas.load("foxglove.FrameTransforms"))
        found = origins(message, "r2/Torso")
        hands = arms.hands(angles)
        for side, hand in zip("LR", hands, strict=True):
            assert np.allclose(found[f"r2/{side}Hand"], hand, atol=1e-9), (side, angles)
        # every joint frame, not only the hand's: frame i of an arm is where kinematics puts it
        for i in range(len(arms.joints[0])):
            points = arms.points(np.array([[angles[j] for j in arm] for arm in arms.joints]), upto=i)
            for arm, point in zip(arms.joints, points, strict=True):
                assert np.allclose(found[f"r2/{arm[i]}"], point, atol=1e-9)


@pytest.mark.parametrize("model", ["pepper", "nao"])
def test_the_urdf_test_vectors(model):
    vectors = fk_vectors(model)
    assert vectors
    for name, vector in vectors.items():
        found = origins(ArmFrames.of(model).transforms(model, frame_of(vector.get("q", {}))), f"{model}/Torso")
        assert np.allclose(found[f"{model}/{vector['chain'][-1]}"], vector["pos"], atol=1e-5), name


def test_one_transform_per_arm_joint_with_the_frame_time():
    message = ArmFrames.of("pepper").transforms("pepper", frame_of({"HeadYaw": 0.3}, t=12.000000001))
    children = [tf["child_frame_id"] for tf in message["transforms"]]
    assert children == [f"pepper/{s}{j}" for s in "LR" for j in
                        ("ShoulderPitch", "ShoulderRoll", "ElbowYaw", "ElbowRoll", "WristYaw", "Hand")]
    assert {(tf["timestamp"]["sec"], tf["timestamp"]["nsec"]) for tf in message["transforms"]} == {(12, 1)}


def test_models_without_kinematics_get_no_transforms():
    assert arm_frames({"model": "robbie"}) is None
    assert arm_frames(None) is None and arm_frames({}) is None
    assert arm_frames({"model": "nao"}) is ArmFrames.of("nao")


@pytest.mark.parametrize(("event", "line", "level"), [
    ({"kind": "behavior", "name": "animations/Stand/Gestures/Hey_1", "state": "started"},
     "behavior animations/Stand/Gestures/Hey_1 started", 2),
    ({"kind": "behavior", "name": "x/y", "state": "failed"}, "behavior x/y failed", 3),
    ({"kind": "speech", "text": "hello there", "state": "done"}, 'speech "hello there" done', 2),
    ({"kind": "connection", "state": "lost"}, "connection lost", 3),
    ({"kind": "posture", "name": "Stand", "state": "reached"}, "posture Stand reached", 2),
    ({"kind": "motion", "chain": "RArm", "state": "onset", "seq": 3}, "motion RArm onset", 2),
    ({"kind": "command", "verb": "behavior/run", "args": {"name": "a"}, "ok": True}, "command behavior/run ok", 2),
    ({"kind": "command", "verb": "say", "args": {}, "ok": False, "error": "conflict: owned by x"},
     "command say refused: conflict: owned by x", 3),
    ({"kind": "conflict", "state": "standby", "owner": {"host": "h", "node": "n", "since": 1.0}},
     "conflict owner n on h standby", 3),
    ({"kind": "tick"}, "tick", 2),
])
def test_an_event_as_a_log_line(event, line, level):
    message = log_message("pepper", {"t": 1763900000.75, **event})
    jsonschema.validate(message, schemas.load("foxglove.Log"))
    assert message == {"timestamp": {"sec": 1763900000, "nsec": 750000000}, "level": level, "message": line,
                       "name": f"pepper/{event['kind']}", "file": "", "line": 0}
