"""Joint streams and robot info from a (fake) NAOqi robot."""

from __future__ import annotations

import struct

import pytest

from sonibus import schemas
from sonibus.bus import load_model, robot_info

from ..conftest import wait_for
from ..pacing import drift_frames
from .conftest import RATE_HZ


def f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


@pytest.mark.parametrize("robot", ["pepper", "nao"])
def test_streams_every_joint_at_rate_zipped_by_name(rig, robot):
    r = rig(robot, status_every_s=0.5)
    fake = r.fake
    assert list(fake.body_names) != list(load_model(robot).joint_names)  # the fake shuffles, we must not care
    fake.engine.joints_set(["HeadYaw", "HeadPitch"], [0.7, -0.3], 1.0)
    frame = r.joints.wait_pose({"HeadYaw": f32(0.7), "HeadPitch": f32(-0.3)}, timeout=5.0)
    pose = fake.engine.body.pose()
    assert set(frame) == set(fake.body_names)
    for name, value in frame.items():
        assert value == f32(pose[name]), name  # the exact float32 ALMemory holds, under its own name
    frames = r.joints.next(RATE_HZ)  # one second of frames
    seqs = [s for s, _ in frames]
    # A busy machine makes the adapter skip frames (a gap in seq, by design); the rate itself is
    # bench/naoqi_rate.py's figure. Here: frames in seq order, most of them there, paced by seq.
    assert seqs == sorted(set(seqs)) and seqs[-1] - seqs[0] < 2 * len(seqs), f"at {RATE_HZ} Hz: {seqs}"
    drift = drift_frames([(s, r.joints.t[s]) for s in seqs], RATE_HZ)
    assert abs(drift) <= 1.0, f"seq drifts from t by {drift:.1f} frames in a second"  # paced by seq, not by luck
    status = r.events.wait("status", timeout=3.0)
    assert 0 < status["rate_hz"] <= 1.2 * RATE_HZ  # the achieved rate, in Hz: never above the configured one
    assert 0 < status["read_ms"] < 100 and status["source"] == "almemory"  # (a median: a stall does not move it)
    for _, message in r.joints.samples[:100]:
        schemas.validate("joint_sample", message)


def test_robot_info_comes_from_the_robot(rig):
    r = rig("nao")
    info = robot_info(r.bus, "nao")
    schemas.validate("robot_info", info)
    model = load_model("nao")
    assert info["model"] == "nao" and info["adapter"] == "naoqi"
    assert [j["name"] for j in info["joints"]] == list(model.joint_names)  # reference order, not the robot's
    for joint in info["joints"]:
        spec = model.joint(joint["name"])
        assert joint["min"] == f32(spec.min) and joint["max"] == f32(spec.max)  # getLimits, not robots.json
        assert joint["max_velocity"] == f32(spec.max_velocity) and joint["chain"] == spec.chain
        assert joint["unit"] == spec.unit
    assert info["behaviors"] == sorted(r.fake.engine.behaviors())
    assert set(info["postures"]) == set(model.postures)
    naoqi = info["naoqi"]
    assert naoqi["connected"] is True and naoqi["body_type"] == "Nao" and naoqi["cycle_ms"] == 10
    assert naoqi["source"] == "almemory" and naoqi["speech_events"] == "subscriber"
    assert naoqi["limits_differ"] == []
    wait_for(lambda: robot_info(r.bus, "nao")["naoqi"]["rate_hz"] > 0, what="an achieved rate in the info")


def test_extra_quantities_are_sample_fields(rig):
    r = rig(extra=("cmd", "cur", "temp"))
    r.fake.engine.joints_set(["HeadYaw"], [1.0], 0.2)
    sample = wait_for(lambda: (r.joints.poll().get("pepper/joints/HeadYaw") or {}).get("cmd") == f32(1.0)
                      and r.joints.latest["pepper/joints/HeadYaw"], what="the commanded angle in a sample")
    assert sample["v"] != sample["cmd"]  # still on its way
    assert sample["temp"] == 35.0 and sample["cur"] == pytest.approx(0.1)
    schemas.validate("joint_sample", sample)


@pytest.mark.parametrize(("source", "values"), [("motion", range(20, 41)), ("almemory", range(1, 4))])
def test_sources_on_a_nao_v6_mirror(rig, source, values):
    """NAO V6 mirrors sensors into ALMemory every 500 ms; ALMotion.getAngles is current."""
    r = rig("nao", fake={"almemory_period_ms": 500}, source=source)
    assert robot_info(r.bus, "nao")["naoqi"]["source"] == source
    r.fake.engine.joints_set(["HeadYaw"], [1.0], 0.05)  # 0.41 rad/s: 2.4 s
    frames = r.joints.next(40)  # 0.8 s, and more if a busy machine made the adapter skip frames:
    seen = {f["HeadYaw"] for _, f in frames}
    more = (frames[-1][0] - frames[0][0] + 1 - len(frames)) // 25  # one more refresh each 0.5 s skipped
    assert min(values) <= len(seen) <= max(values) + more, f"{len(seen)} HeadYaw values in 40 frames from {source}"
