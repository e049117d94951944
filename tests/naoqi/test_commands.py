"""Every command reaches the (fake) robot and moves it; every bad one is refused
before it does; behavior, speech and posture events come back."""

from __future__ import annotations

import pytest

from sonibus.bus import CommandError, load_model, robot_info, send_command

from ..conftest import wait_for
from .test_stream import f32

NOD = "animations/Stand/Gestures/Yes_1"
SKY = "animations/Stand/Gestures/ShowSky_1"


def test_joints_set_moves_the_robot(rig):
    r = rig()
    assert send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw", "LShoulderPitch"],
                                                         "angles": [0.5, 0.4], "speed": 1.0}) == \
        {"targets": {"HeadYaw": 0.5, "LShoulderPitch": 0.4}, "speed": 1.0}  # (issue 37: what was sent; it was {})
    wait_for(lambda: not r.fake.engine.body.moving(), what="the robot to stop moving")
    pose = r.fake.engine.body.pose()
    assert (pose["HeadYaw"], pose["LShoulderPitch"]) == pytest.approx((0.5, 0.4))


@pytest.mark.parametrize("subscriber", ["ok", "invalid-signature"])
def test_behavior_run_stop_and_their_events(rig, subscriber):
    r = rig(fake={"subscriber": subscriber})
    assert send_command(r.bus, "pepper", "behavior/run", {"name": SKY}) == {"name": SKY}
    assert r.fake.engine.running_behavior == SKY
    r.events.wait("behavior", name=SKY, state="started")
    with pytest.raises(CommandError) as running:
        send_command(r.bus, "pepper", "behavior/run", {"name": SKY})
    assert running.value.code == "failed" and SKY in running.value.message
    assert send_command(r.bus, "pepper", "behavior/stop", {"name": SKY}) == {"was_running": True}
    assert r.fake.engine.running_behavior is None
    # issue 37, item 9: a behavior cut short and one that finished both read "stopped"; `end` says which
    r.events.wait("behavior", name=SKY, state="stopped", end="cut")
    assert send_command(r.bus, "pepper", "behavior/stop", {}) == {"was_running": False}
    send_command(r.bus, "pepper", "behavior/run", {"name": NOD})
    r.events.wait("behavior", timeout=5.0, name=NOD, state="stopped", end="finished")  # ends by itself
    send_command(r.bus, "pepper", "behavior/run", {"name": SKY})
    r.events.wait("behavior", name=SKY, state="started")
    send_command(r.bus, "pepper", "stop", {})
    r.events.wait("behavior", name=SKY, state="stopped", end="cut")


def test_say_queues_and_speech_events_name_the_texts(rig):
    r = rig()
    tts = r.fake.services["ALTextToSpeech"]
    assert send_command(r.bus, "pepper", "say", {"text": "one two", "speed": 300, "volume": 0.5}) == {"queued": 0}
    assert send_command(r.bus, "pepper", "say", {"text": "three"}) == {"queued": 1}
    wait_for(lambda: r.fake.engine.speaking, what="the robot speaking")
    for text in ("one two", "three"):
        r.events.wait("speech", timeout=5.0, text=text, state="started")
        r.events.wait("speech", timeout=5.0, text=text, state="done")
    assert [e["text"] for e in r.events.find("speech", state="started")] == ["one two", "three"]
    assert (tts.volume, tts.parameters["speed"]) == (1.0, 100.0)  # the second text had the robot's defaults
    assert r.adapter.robot_info()["naoqi"]["speech_events"] == "subscriber"


def test_speech_events_by_polling_where_subscribing_fails(rig):
    """qi 3.x against NAOqi 2.5: ALMemory.subscriber raises "Invalid signature"."""
    r = rig(fake={"subscriber": "invalid-signature"})
    assert r.adapter.robot_info()["naoqi"]["speech_events"] == "polling"
    for text in ("first words", "second words"):
        send_command(r.bus, "pepper", "say", {"text": text, "speed": 400})
        started = r.events.wait("speech", timeout=5.0, text=text, state="started")
        done = r.events.wait("speech", timeout=5.0, text=text, state="done")
        assert done["t"] > started["t"]
    assert len(r.events.find("speech")) == 4


def test_posture_goes_there_and_says_so(rig):
    r = rig()
    assert send_command(r.bus, "pepper", "posture", {"name": "Crouch", "speed": 1.0}) == {"name": "Crouch"}
    r.events.wait("posture", timeout=5.0, name="Crouch", state="reached")
    target = load_model("pepper").posture("Crouch")
    assert r.fake.engine.body.pose() == pytest.approx(target)
    send_command(r.bus, "pepper", "posture", {"name": "Stand", "speed": 0.1})
    r.events.wait("posture", name="Stand", state="started")
    send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.3]})
    r.events.wait("posture", name="Stand", state="interrupted")
    assert [e["state"] for e in r.events.find("posture")] == ["started", "reached", "started", "interrupted"]


def test_stiffness_and_awareness(rig):
    r = rig()
    model = load_model("pepper")
    assert send_command(r.bus, "pepper", "stiffness", {"names": ["RArm"], "value": 0.5}) == \
        {"joints": list(model.chain("RArm"))}
    stiffness = dict(zip(model.joint_names, r.fake.engine.body.stiffness, strict=True))
    assert {j for j, v in stiffness.items() if v == 0.5} == set(model.chain("RArm"))
    assert send_command(r.bus, "pepper", "awareness", {"enabled": True}) == {"enabled": True, "previous": False}
    assert r.fake.engine.aware is True
    assert send_command(r.bus, "pepper", "awareness", {"enabled": False}) == {"enabled": False, "previous": True}
    assert r.fake.engine.aware is False


def test_the_info_says_whether_awareness_is_on_and_follows_a_change_made_elsewhere(rig):
    """Issue 29, item 3: the operator page's checkbox starts from the info's ``awareness``.
    Read on connection, set by the command at once, and a change made on the robot by
    something else (Choregraphe, autonomous life) followed within two status periods;
    enabled but paused is off (the robot does not look at people)."""
    r = rig(fake={"idle": True}, status_every_s=0.1)

    def said() -> bool | None:
        return robot_info(r.bus, "pepper")["awareness"]

    assert said() is True
    send_command(r.bus, "pepper", "awareness", {"enabled": False})
    assert said() is False
    r.fake.engine.awareness(True)  # (elsewhere: not through the adapter)
    wait_for(lambda: said() is True, what="the info to follow awareness turned on elsewhere")
    r.fake.services["ALBasicAwareness"].paused = True
    wait_for(lambda: said() is False, what="the info to say a paused awareness is off")


def test_stop_halts_behavior_motion_and_speech(rig):
    r = rig()
    send_command(r.bus, "pepper", "behavior/run", {"name": SKY})
    send_command(r.bus, "pepper", "say", {"text": "a long sentence to be cut short by a stop"})
    r.events.wait("speech", state="started")
    assert send_command(r.bus, "pepper", "stop", {})["held"] is True
    assert r.fake.engine.running_behavior is None and not r.fake.engine.speaking
    assert not r.fake.engine.body.moving()
    r.events.wait("speech", state="done")
    assert send_command(r.bus, "pepper", "stop", "whatever")["held"] is True  # stop takes any payload


@pytest.mark.parametrize(("verb", "args", "code"), [
    ("joints/set", {"names": ["HeadYawn"], "angles": [0.1]}, "unknown_joint"),
    ("joints/set", {"names": ["HeadYaw"], "angles": [float("nan")]}, "bad_request"),
    ("joints/set", {"names": ["HeadPitch"], "angles": [1.2]}, "out_of_range"),
    ("joints/set", {"names": ["HeadYaw"], "angles": [0.1], "speed": 0}, "out_of_range"),
    ("behavior/run", {"name": "animations/Fly_1"}, "unknown_behavior"),
    ("posture", {"name": "Sit"}, "unknown_posture"),
    ("say", {"text": "x" * 501}, "bad_request"),
    ("stiffness", {"names": ["Tail"], "value": 0.0}, "unknown_joint"),
])
def test_bad_requests_never_reach_the_robot(rig, verb, args, code):
    r = rig()
    engine, before = r.fake.engine, r.fake.engine.body.pose()
    with pytest.raises(CommandError) as refused:
        send_command(r.bus, "pepper", verb, args)
    assert refused.value.code == code
    assert engine.body.pose() == before and not engine.body.moving()
    assert engine.running_behavior is None and not engine.speaking


def test_pause_awareness_while_running_restored_on_stop(rig):
    r = rig(pause_awareness=True)
    awareness = r.fake.services["ALBasicAwareness"]
    wait_for(lambda: awareness.paused, what="awareness paused")
    r.adapter.stop()
    assert awareness.paused is False


def test_a_robot_error_is_a_failed_reply_on_one_line(rig, monkeypatch):
    r = rig()

    def fall(name: str, speed: float) -> None:
        raise CommandError("failed", "ALRobotPosture: the robot has fallen")

    monkeypatch.setattr(r.fake.engine, "posture", fall)
    assert send_command(r.bus, "pepper", "posture", {"name": "Crouch"}) == {"name": "Crouch"}
    r.events.wait("posture", name="Crouch", state="interrupted")  # goToPosture fails in the background
    monkeypatch.setattr(r.fake.engine, "behaviors", list)  # uninstalled behind the adapter's back
    with pytest.raises(CommandError) as failed:
        send_command(r.bus, "pepper", "behavior/run", {"name": NOD})
    assert failed.value.code == "failed" and "\n" not in failed.value.message
    assert "Behavior not found" in failed.value.message and NOD in failed.value.message


@pytest.mark.parametrize(("subscriber", "mode"), [("ok", "subscriber"), ("invalid-signature", "polling")])
def test_speech_keys_raised_only_by_the_first_say(rig, subscriber, mode):
    """A robot that has not spoken since it booted has no ALTextToSpeech/Text* keys yet: speech
    events still come once it speaks, and joints keep coming from ALMemory throughout."""
    r = rig(fake={"speech_keys": "after-first-say", "subscriber": subscriber})
    assert "ALTextToSpeech/TextDone" not in r.fake.memory
    naoqi = robot_info(r.bus, "pepper")["naoqi"]
    assert (naoqi["source"], naoqi["speech_events"]) == ("almemory", mode)
    for text in ("first words", "second words"):
        send_command(r.bus, "pepper", "say", {"text": text, "speed": 300})
        r.events.wait("speech", timeout=5.0, text=text, state="started")
        r.events.wait("speech", timeout=5.0, text=text, state="done")
    naoqi = robot_info(r.bus, "pepper")["naoqi"]
    assert (naoqi["source"], naoqi["speech_events"]) == ("almemory", mode)
    r.fake.engine.joints_set(["HeadYaw"], [0.25], 1.0)
    r.joints.wait_pose({"HeadYaw": f32(0.25)})


def test_the_published_limit_is_accepted_and_errors_show_rounded_numbers(rig):
    """docs give HeadYaw's limit as 2.08567; the robot's getLimits says 2.085669994354248 (float32)."""
    r = rig()
    for limit in (2.08567, -2.08567):
        assert send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [limit],
                                                             "speed": 1.0})["targets"]["HeadYaw"] == \
            pytest.approx(limit, abs=1e-6)
        wait_for(lambda: not r.fake.engine.body.moving(), what="the head to get there")
        assert abs(r.fake.engine.body.pose()["HeadYaw"]) <= f32(2.08567)  # clamped to the robot's own limit
    with pytest.raises(CommandError) as refused:
        send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [2.09]})
    assert refused.value.code == "out_of_range"
    assert "HeadYaw = 2.09 is outside its limits [-2.08567, 2.08567] rad" in refused.value.message
