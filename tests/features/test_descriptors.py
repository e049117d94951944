"""The expressive descriptors past the Laban Efforts (issue 36): kinetic energy, points
density and symmetry against PyEyesWeb 1.1.1 (test extra, pinned), the head in joint space,
per-segment values (closed forms of /work/shared/reference/expressive.md) and the golden
values of the simulator's Hey_1 (tests/features/hey_1.json)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from monalysa.quality.smoothness import log_dimensionless_jerk
from monalysa.quality.smoothness import sparc as monalysa_sparc
from pyeyesweb.low_level import GeometricSymmetry, KineticEnergy, PointsDensity

from sonibus import schemas
from sonibus.adapters.features import FeaturesConfig
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.segments import SegmentRecorder
from sonibus.adapters.features.table import describe as describe_robot
from sonibus.adapters.sim.offline import play
from sonibus.bus import load_model

GOLDEN = Path(__file__).with_name("hey_1.json")
MIRROR = {"ShoulderPitch": 1, "ShoulderRoll": -1, "ElbowYaw": -1, "ElbowRoll": -1, "WristYaw": -1}


def robot_features(model: str = "pepper", features: tuple[str, ...] = ("expressive",)) -> RobotFeatures:
    info = {"model": model, "joints": [j.to_info() for j in load_model(model).joints]}
    return RobotFeatures(describe_robot(model, info), FeaturesConfig(features=features))


def arms_pose(t: float) -> dict[str, float]:
    """Both arms moving, differently: a pose that is neither still nor mirrored."""
    right = {"ShoulderPitch": 0.3 + 0.8 * math.sin(2 * t), "ShoulderRoll": -0.3 - 0.2 * math.sin(3 * t),
             "ElbowYaw": 1.2, "ElbowRoll": 0.8 + 0.3 * math.cos(t), "WristYaw": 0.4}
    left = {"ShoulderPitch": 0.5 - 0.6 * math.cos(t), "ShoulderRoll": 0.4, "ElbowYaw": -1.0 + 0.2 * t,
            "ElbowRoll": -0.6, "WristYaw": 0.0}
    return {**{f"pepper/joints/R{k}": v for k, v in right.items()},
            **{f"pepper/joints/L{k}": v for k, v in left.items()}}


def test_kinetic_energy_points_density_and_symmetry_equal_pyeyesweb():
    """The node's values on the real FK, frame by frame, equal PyEyesWeb's on the same points
    (its symmetry mirrors axis 0 about a centre joint: the lateral axis is put first and the
    Torso origin given as the centre)."""
    features = robot_features()
    arms = features.robot.arms
    index = features.robot.arm_joints
    elbow = features._expressive.elbow
    assert elbow is not None
    checked = 0
    for k in range(60):
        t = k / 50
        frame = {f"pepper/joints/{j}": 0.0 for j in load_model("pepper").joint_names} | arms_pose(t)
        got = {key.split("/", 2)[2]: m["v"] for key, m in features.step(t, k + 1, frame).samples}
        q = np.array([[frame[f"pepper/joints/{j}"] for j in arm] for arm in arms.joints])
        assert index is not None and q.shape == index.shape
        hands, elbows = arms.points(q), arms.points(q, elbow)
        density = PointsDensity().compute(np.concatenate([hands, elbows])).points_density
        assert got["points_density/arms"] == pytest.approx(density, rel=1e-12)
        lateral_first = np.vstack([hands, np.zeros(3)])[:, [1, 0, 2]]
        sym = GeometricSymmetry([(0, 1)], center_of_symmetry=2).compute(lateral_first).pairs["0_1"]
        assert got["symmetry/arms"] == pytest.approx(sym, rel=1e-12)
        assert got["hand_distance/arms"] == pytest.approx(np.linalg.norm(hands[0] - hands[1]), rel=1e-12)
        if "kinetic_energy/L" in got:  # from the fit's velocity, as its Laban Weight is
            v = features._expressive.hand_velocity
            energy = KineticEnergy().compute(v).joints
            assert got["kinetic_energy/L"] == pytest.approx(energy["0"]["total"], rel=1e-12)
            assert got["kinetic_energy/R"] == pytest.approx(energy["1"]["total"], rel=1e-12)
            checked += 1
    assert checked > 30


@pytest.mark.parametrize("fs", [50, 100])
def test_mirrored_arms_give_symmetry_1_and_the_swept_hand_its_energy(fs):
    """The reference's shoulder sweep (RShoulderPitch at 1 rad/s, r = 0.310452 m) with the left
    arm mirrored (pitch equal, roll and yaw negated): symmetry exactly 1, each hand's kinetic
    energy ½(ωr)², fluidity 1/ω on the circle."""
    features = robot_features()
    pose = {f"pepper/joints/{j}": 0.0 for j in load_model("pepper").joint_names}
    right = {"ShoulderRoll": -0.3, "ElbowYaw": 1.2, "ElbowRoll": 0.8, "WristYaw": 0.4}
    last: dict[str, float] = {}
    symmetries = []
    for k in range(fs):
        t = k / fs
        arm = {**right, "ShoulderPitch": -0.5 + t}
        pose.update({f"pepper/joints/R{j}": v for j, v in arm.items()})
        pose.update({f"pepper/joints/L{j}": v * MIRROR[j] for j, v in arm.items()})
        for key, msg in features.step(t, k + 1, pose).samples:
            last[key.split("/", 2)[2]] = msg["v"]
            if key.endswith("symmetry/arms"):
                symmetries.append(msg["v"])
    r = 0.310452
    assert len(symmetries) == fs and min(symmetries) == pytest.approx(1.0, abs=1e-12)
    for side in "LR":
        assert last[f"kinetic_energy/{side}"] == pytest.approx(0.5 * r**2, rel=2e-3)
        assert last[f"fluidity/{side}"] == pytest.approx(1.0, rel=2e-3)  # ⟨ωr⟩/⟨ω²r⟩ = 1/ω, ω = 1 rad/s


@pytest.mark.parametrize("fs", [50, 100])
def test_the_head_in_joint_space(fs):
    """HeadYaw at 1 rad/s and HeadPitch at 0.5 rad/s: joint-space speed² 1.25, energy 0.625,
    Time 0, a straight path (Space 1); the legs, still, publish no Space."""
    features = robot_features()
    pose = {f"pepper/joints/{j}": 0.0 for j in load_model("pepper").joint_names}
    last: dict[str, float] = {}
    for k in range(fs):
        t = k / fs
        pose.update({"pepper/joints/HeadYaw": -0.5 + t, "pepper/joints/HeadPitch": -0.3 + 0.5 * t})
        for key, msg in features.step(t, k + 1, pose).samples:
            last[key.split("/", 2)[2]] = msg["v"]
    assert last["kinetic_energy/Head"] == pytest.approx(0.625, rel=1e-9)
    assert last["laban_weight/Head"] == pytest.approx(1.25, rel=1e-9)
    assert last["laban_time/Head"] < 1e-9
    assert last["laban_space/Head"] == pytest.approx(1.0, rel=1e-9)
    assert "laban_space/Leg" not in last and last["kinetic_energy/Leg"] < 1e-20


def reach(fs: float, drop: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The reference's minimum-jerk reach (D = 0.3 m, T = 1 s) sampled at ``fs``, a fraction
    ``drop`` of its inner frames left out."""
    t = np.arange(0, 1 + 0.5 / fs, 1 / fs)
    keep = np.random.default_rng(seed).random(len(t)) >= drop
    keep[[0, -1]] = True
    t = t[keep]
    s = 0.3 * (10 * t**3 - 15 * t**4 + 6 * t**5)
    return t, np.c_[s, np.zeros_like(s), np.zeros_like(s)]


def segment_of(t: np.ndarray, points: np.ndarray) -> dict[str, float]:
    recorder = SegmentRecorder(min_duration_s=0.08)
    recorder.change("onset", t[0])
    for time_, p in zip(t, points, strict=True):
        recorder.add(time_, p)
    segment = recorder.change("offset", t[-1])
    assert segment is not None
    return segment


@pytest.mark.parametrize(("fs", "sampled"), [(50, -5.2804), (100, -5.3016)])
def test_a_minimum_jerk_segment(fs, sampled):
    """Per segment: duration 1 s, path 0.3 m, directness exactly 1, peak speed 1.875 D/T, fluidity
    T/3.75, SPARC −1.4058, LDLJ near the sampled closed form (its speed by central differences);
    SPARC and LDLJ equal monalysa's on the same speed profile."""
    t, points = reach(fs)
    s = segment_of(t, points)
    assert s["duration_s"] == pytest.approx(1.0, abs=1e-12) and "pause_s" not in s
    assert s["path"] == pytest.approx(0.3, rel=1e-12)
    assert s["directness"] == pytest.approx(1.0, abs=1e-12)
    assert s["peak_speed"] == pytest.approx(0.5625, rel=2e-3)
    assert s["fluidity"] == pytest.approx(1 / 3.75, rel=1e-2)
    assert s["sparc"] == pytest.approx(-1.4058, abs=5e-3)
    assert s["ldlj"] == pytest.approx(sampled, abs=2e-2)
    speed = np.abs(np.gradient(points[:, 0], 1 / fs))
    assert s["sparc"] == pytest.approx(monalysa_sparc(speed, fs)[0], abs=1e-6)
    assert s["ldlj"] == pytest.approx(log_dimensionless_jerk(speed, fs), abs=1e-6)


def test_a_segment_with_20_percent_of_frames_dropped():
    """Resampled at the frames' median rate, a 100 Hz reach missing 20 % of its frames gives the
    same segment within the 50 Hz tolerances."""
    full, dropped = segment_of(*reach(100)), segment_of(*reach(100, drop=0.2, seed=3))
    for name, tol in {"duration_s": 1e-12, "path": 1e-3, "directness": 1e-12, "peak_speed": 2e-3,
                      "sparc": 5e-3}.items():
        assert dropped[name] == pytest.approx(full[name], rel=tol, abs=tol), name


def test_pause_before_a_segment():
    recorder = SegmentRecorder(min_duration_s=0.08)
    for k in range(300):
        t = k / 100
        recorder.add(t, np.array([0.1 * t, 0.0]))
        for at, state in ((0.2, "onset"), (0.9, "offset"), (1.5, "onset"), (2.5, "offset")):
            if abs(t - at) < 1e-9:
                segment = recorder.change(state, t)
                assert (segment is None) == (state == "onset")
    assert segment["pause_s"] == pytest.approx(0.6) and segment["duration_s"] == pytest.approx(1.0)
    assert segment["path"] == pytest.approx(0.1, rel=1e-9)


@settings(max_examples=15, deadline=None)
@given(shift=st.floats(-2, 2), angle=st.floats(0, 2 * math.pi), scale=st.floats(0.2, 5),
       slow=st.sampled_from([0.5, 1.0, 2.0]))
def test_segment_invariance(shift, angle, scale, slow):
    """Translating or rotating a segment changes nothing; space × s scales path and peak speed
    by s; time × c divides peak speed by c, multiplies duration and fluidity by c and keeps
    directness, SPARC (its normalised arc length) and LDLJ (dimensionless)."""
    t, points = reach(100)
    c, s_ = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    base = segment_of(t, points)
    moved = segment_of(t * slow, scale * points @ rot.T + shift)
    assert moved["duration_s"] == pytest.approx(base["duration_s"] * slow, rel=1e-9)
    assert moved["path"] == pytest.approx(base["path"] * scale, rel=1e-9)
    assert moved["directness"] == pytest.approx(base["directness"], rel=1e-9)
    assert moved["peak_speed"] == pytest.approx(base["peak_speed"] * scale / slow, rel=1e-6)
    assert moved["fluidity"] == pytest.approx(base["fluidity"] * slow, rel=1e-6)
    assert moved["ldlj"] == pytest.approx(base["ldlj"], abs=1e-6)
    if slow == 1.0:  # SPARC's 10 Hz cut-off and 2^k padding depend on the samples' count and rate
        assert moved["sparc"] == pytest.approx(base["sparc"], abs=1e-6)


def test_symmetry_and_density_scale_as_they_should():
    """Symmetry is a ratio (scaling leaves it), points density and hand distance scale with space."""
    from sonibus.adapters.features.shape import points_density, symmetry

    rng = np.random.default_rng(5)
    for _ in range(20):
        p, s = rng.normal(size=(4, 3)), rng.uniform(0.1, 10)
        assert symmetry(s * p[0], s * p[1]) == pytest.approx(symmetry(p[0], p[1]), abs=1e-9)  # (ε = 1e-10)
        assert points_density(s * p + 3.0) == pytest.approx(s * points_density(p), rel=1e-9)


def hey_1(fs: int) -> list[dict]:
    """The motion events of the sim's Hey_1 at ``fs`` (started 0.5 s in, 4.5 s of frames)."""
    model = load_model("pepper")
    features = robot_features("pepper", ("motion", "expressive"))
    events = []
    for k, (t, positions) in enumerate(play(model, "animations/Stand/Gestures/Hey_1", fs, 4.5)):
        out = features.step(t, k + 1, dict(zip([f"pepper/joints/{n}" for n in model.joint_names], positions,
                                               strict=True)))
        events += [m for _, m in out.events]
    return events


@pytest.mark.parametrize("fs", [50, 100])
def test_hey_1_golden_values(fs):
    """The onsets, offsets and segment values of Hey_1 as kept in hey_1.json (rewrite it with
    SONIBUS_GOLDEN=1 after a deliberate change, and say why in the commit)."""
    events = hey_1(fs)
    if os.environ.get("SONIBUS_GOLDEN"):
        kept = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
        GOLDEN.write_text(json.dumps({**kept, str(fs): events}, indent=1) + "\n")
    golden = json.loads(GOLDEN.read_text())[str(fs)]
    for event in events:
        schemas.validate("event", event)
    assert [(e["chain"], e["state"], e["seq"]) for e in events] == [(e["chain"], e["state"], e["seq"])
                                                                      for e in golden]
    assert [e["chain"] for e in events if e["state"] == "offset"] == ["Head", "Head", "RArm"]
    for got, want in zip(events, golden, strict=True):
        assert got["t"] == pytest.approx(want["t"], abs=1e-12)
        assert set(got.get("segment", {})) == set(want.get("segment", {}))
        for name, value in want.get("segment", {}).items():
            assert got["segment"][name] == pytest.approx(value, rel=1e-6, abs=1e-9), (got["chain"], name)


def test_a_segment_recorder_keeps_a_bounded_path():
    """A chain that never stops (70 s at 100 Hz) keeps its last max_s (60 s, trimmed by the
    second) of frames, not all; its segment still lasts from its onset crossing; a still chain
    keeps only the little before an onset."""
    recorder = SegmentRecorder(min_duration_s=0.08, max_s=60.0)
    recorder.change("onset", 0.0)
    for k in range(7001):
        recorder.add(k / 100, np.array([math.cos(k / 100), math.sin(k / 100)]))
        assert len(recorder._times) <= 61 * 100 + 1
    segment = recorder.change("offset", 70.0)
    assert segment["duration_s"] == pytest.approx(70.0) and 60.0 <= segment["path"] <= 61.0  # (1 m/s)
    for k in range(7001, 9001):
        recorder.add(k / 100, np.zeros(2))
    assert len(recorder._times) <= (recorder.keep_s + 1) * 100 + 1


def test_a_ros2_arm_from_its_urdf_gets_its_chains_descriptors():
    """A URDF robot (tests/ros2's arm: chains tool, finger, camera, a prismatic joint): each
    chain's hand descriptors under its own name, no `arms` values (no L and R), every key
    published described on info/derived."""
    from sonibus.adapters.features.catalog import derived
    from sonibus.adapters.ros2.description import describe as describe_urdf
    from sonibus.adapters.ros2.urdf import parse

    from ..ros2.conftest import ARM_URDF, CHAINS

    arm = describe_urdf(parse(ARM_URDF.read_text(), str(ARM_URDF)), CHAINS)
    joints = [j.to_info() for j in arm.model.joints]
    info = {"model": arm.model.name, "joints": joints, "kinematics": arm.kinematics}
    robot = describe_robot("arm", info)
    assert robot.arms is not None, robot.unavailable
    config = FeaturesConfig(features=("motion", "expressive"))
    features = RobotFeatures(robot, config)
    seen: set[str] = set()
    for k in range(100):
        t = k / 50
        frame = {f"arm/joints/{j['name']}": (j["min"] + j["max"]) / 2 + 0.2 * (j["max"] - j["min"]) *
                 math.sin(2 * t + i) for i, j in enumerate(joints)}
        for key, message in features.step(t, k + 1, frame).samples:
            assert math.isfinite(message["v"]), key
            seen.add(key)
    assert {f"arm/derived/laban_weight/{chain}" for chain in CHAINS} <= seen
    assert not any(key.endswith("/arms") for key in seen)
    reply = derived(robot, config, {"host": "h", "node": "features"})
    schemas.validate("derived_info", reply)
    assert seen <= {e["key"] for e in reply["derived"]}
