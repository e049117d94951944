"""Our URDF reading and forward kinematics against yourdfpy's, on a robot with several
chains (prismatic, continuous, fixed joints folded in, a mimic joint); the features'
hands and Foxglove's transforms from the chains a robot's info carries."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yourdfpy

from sonibus.adapters.features.kinematics import from_info
from sonibus.adapters.foxglove.convert import arm_frames, multiply, rotate
from sonibus.adapters.ros2.description import describe
from sonibus.adapters.ros2.urdf import UrdfError, group_states, parse

from .conftest import ARM_URDF, CHAINS

REFERENCE = yourdfpy.URDF.load(str(ARM_URDF), build_scene_graph=True, load_meshes=False)


@pytest.fixture(scope="module")
def arm():
    return describe(parse(ARM_URDF.read_text(), str(ARM_URDF)), CHAINS)


def _configurations(arm, count=25):
    rng = np.random.default_rng(28)
    for _ in range(count):
        q = {j.name: float(rng.uniform(j.min, j.max)) for j in arm.model.joints if j.name not in arm.mimics}
        q["torso_yaw"] = float(rng.uniform(-9.0, 9.0))  # continuous: any angle
        yield q


def test_the_joint_table_is_yourdfpys(arm):
    assert set(arm.model.joint_names) == set(REFERENCE.actuated_joint_names) | {"finger_right"}
    for joint in arm.model.joints:
        theirs = REFERENCE.joint_map[joint.name]
        if theirs.type == "continuous":
            assert (joint.min, joint.max) == (-math.pi, math.pi)
        else:
            assert (joint.min, joint.max) == (theirs.limit.lower, theirs.limit.upper)
        assert joint.max_velocity == theirs.limit.velocity
        assert joint.unit == ("m" if theirs.type == "prismatic" else "rad")
    assert arm.mimics["finger_right"].multiplier == REFERENCE.joint_map["finger_right"].mimic.multiplier


def test_forward_kinematics_of_every_chain_match_yourdfpy(arm):
    hands = from_info(arm.kinematics)
    assert hands.sides == tuple(CHAINS)
    for q in _configurations(arm):
        REFERENCE.update_cfg(q)
        ours = hands.hands(q)
        theirs = [REFERENCE.get_transform(tip, "base_link")[:3, 3] for tip in CHAINS.values()]
        assert np.allclose(ours, theirs, atol=1e-12), (q, ours, theirs)


def test_foxglove_transforms_compose_to_yourdfpys_frames(arm):
    frames = arm_frames({"model": "sonibus_arm", "kinematics": arm.kinematics})
    assert frames is not None and frames.root == "base_link"
    for q in _configurations(arm, 5):
        REFERENCE.update_cfg(q)
        message = frames.transforms("arm", {"t": 1.0, "seq": 1, "names": list(q), "v": list(q.values())})
        by_child = {t["child_frame_id"]: t for t in message["transforms"]}
        assert len(by_child) == len(message["transforms"])  # shared joints sent once
        for tip in CHAINS.values():
            position, rotation, frame = np.zeros(3), (0.0, 0.0, 0.0, 1.0), f"arm/{tip}"
            chain = []
            while frame != "arm/base_link":
                chain.append(by_child[frame])
                frame = by_child[frame]["parent_frame_id"]
            for t in reversed(chain):
                step = t["translation"]
                position = position + np.array(rotate(rotation, (step["x"], step["y"], step["z"])))
                rotation = multiply(rotation, tuple(t["rotation"][k] for k in "xyzw"))
            assert np.allclose(position, REFERENCE.get_transform(tip, "base_link")[:3, 3], atol=1e-9)


def test_reach_boxes_hold_every_hand_position(arm):
    hands = from_info(arm.kinematics)
    limits = [[(arm.model.joint(n).min, arm.model.joint(n).max) for n in chain] for chain in hands.joints]
    low, high = hands.reach_boxes(limits)
    rng = np.random.default_rng(3)
    for _ in range(300):
        q = {j.name: float(rng.uniform(j.min, j.max)) for j in arm.model.joints}
        points = hands.hands(q)
        assert (points >= low).all() and (points <= high).all()


@pytest.mark.parametrize("text, fault", [
    ("<robot", "not XML"),
    ("<model/>", "the root element is <model>"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
     "</joint></robot>", "needs <limit"),
    ('<robot><link name="a"/><joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint></robot>',
     "names link 'b', which has no <link>"),
    ('<robot><link name="a"/><link name="b"/></robot>', "2 root links"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="continuous"><parent link="a"/><child link="b"/>'
     '<mimic joint="k"/></joint></robot>', "mimics 'k', which is no joint"),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="screw"><parent link="a"/><child link="b"/>'
     "</joint></robot>", "type 'screw'"),
])
def test_a_urdf_that_describes_no_robot_is_refused_naming_why(text, fault):
    with pytest.raises(UrdfError) as refused:
        parse(text, "bad.urdf")
    assert str(refused.value).startswith("bad.urdf: ") and fault in str(refused.value)


def test_chains_and_postures_must_fit_the_urdf():
    urdf = parse(ARM_URDF.read_text(), "arm.urdf")
    with pytest.raises(UrdfError, match="no link 'hand'"):
        describe(urdf, {"tool": "hand"})
    with pytest.raises(UrdfError, match="no movable joint between"):
        describe(urdf, {"base": "base_link"})
    with pytest.raises(UrdfError, match=r"shoulder = 9 is not within its limits \[-1.7, 1.7\]"):
        describe(urdf, postures={"up": {"shoulder": 9}})
    with pytest.raises(UrdfError, match="mimics 'finger_left'"):
        describe(urdf, postures={"open": {"finger_right": -0.02}})
    srdf = ('<robot name="sonibus_arm"><group_state name="home" group="arm"><joint name="shoulder" value="0.5"/>'
            '<joint name="elbow" value="1"/></group_state></robot>')
    assert describe(urdf, postures=group_states(srdf)).model.posture("home") == {"shoulder": 0.5, "elbow": 1.0}
