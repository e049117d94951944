"""The simulator's NAOqi face answers like a NAOqi robot, on a real libqi session."""

from __future__ import annotations

import struct
import time

import pytest
import qi

from sonibus.adapters.sim.naoqi import FakeNaoqi, FakeNaoqiConfig, NaoqiSim
from sonibus.bus import ConfigError, load_model

from ..conftest import free_port, wait_for

POSITION = "Device/SubDeviceList/{}/Position/Sensor/Value"


@pytest.fixture
def endpoint():
    started: list[tuple[FakeNaoqi, qi.Session]] = []

    def start(**options) -> tuple[FakeNaoqi, qi.Session]:
        fake = FakeNaoqi(FakeNaoqiConfig(listen=f"tcp://127.0.0.1:{free_port()}", **options)).start()
        session = qi.Session()
        session.connect(fake.url)
        started.append((fake, session))
        return fake, session

    yield start
    for fake, session in started:
        session.close()
        fake.stop()


def test_body_names_limits_and_values_as_a_robot_gives_them(endpoint):
    _fake, session = endpoint(model="nao")
    motion, memory = session.service("ALMotion"), session.service("ALMemory")
    names = motion.getBodyNames("Body")
    model = load_model("nao")
    assert sorted(names) == sorted(model.joint_names) and list(names) != list(model.joint_names)
    assert memory.getData("RobotConfig/Body/Type") == "Nao"
    for name, (low, high, velocity, _) in zip(names, [motion.getLimits(n)[0] for n in names], strict=True):
        spec = model.joint(name)
        assert (low, high) == pytest.approx((spec.min, spec.max), abs=1e-6) and velocity > 0
    values = memory.getListData([POSITION.format(n) for n in names])
    assert all(struct.unpack("f", struct.pack("f", v))[0] == v for v in values)  # float32, as ALMemory stores
    assert values == pytest.approx(motion.getAngles(names, True), abs=1e-6)


def test_blocking_calls_block_and_signals_fire(endpoint):
    fake, session = endpoint(rate_hz=100)
    behaviors, speech = session.service("ALBehaviorManager"), session.service("ALTextToSpeech")
    seen: list[tuple[str, str]] = []
    behaviors.behaviorStarted.connect(lambda name: seen.append(("started", name)))
    behaviors.behaviorStopped.connect(lambda name: seen.append(("stopped", name)))
    started = time.monotonic()
    behaviors.runBehavior("animations/Stand/Gestures/Yes_1")
    assert time.monotonic() - started > 1.0  # runBehavior returns when the behavior ends
    wait_for(lambda: len(seen) == 2, what="behavior signals")
    assert [s for s, _ in seen] == ["started", "stopped"]
    started = time.monotonic()
    speech.say("one two three four")
    assert time.monotonic() - started > 1.0 and not fake.engine.speaking
    with pytest.raises(RuntimeError, match="Behavior not found"):
        behaviors.startBehavior("animations/Nope")


def test_subscriber_can_fail_as_reported_on_naoqi_2_5(endpoint):
    _, session = endpoint(subscriber="invalid-signature")
    with pytest.raises(RuntimeError, match="Invalid signature"):
        session.service("ALMemory").subscriber("ALTextToSpeech/TextDone")


def test_almemory_can_lag_like_nao_v6_while_almotion_does_not(endpoint):
    _fake, session = endpoint(model="nao", almemory_period_ms=500)
    motion, memory = session.service("ALMotion"), session.service("ALMemory")
    before = memory.getData(POSITION.format("HeadYaw"))
    motion.setAngles(["HeadYaw"], [before + 0.5], 0.05)  # about 1.2 s on the way
    by_motion, by_memory = set(), set()

    def both() -> float:
        by_memory.add(memory.getData(POSITION.format("HeadYaw")))
        by_motion.add(angle := motion.getAngles(["HeadYaw"], True)[0])
        return angle

    started = time.monotonic()
    wait_for(lambda: abs(both() - (before + 0.5)) < 1e-3, what="motion")
    # ALMotion reads anew each call; ALMemory holds each value 500 ms, however often (or late) it is read
    assert len(by_memory) <= (time.monotonic() - started) / 0.5 + 2 < len(by_motion), (by_memory, by_motion)
    wait_for(lambda: memory.getData(POSITION.format("HeadYaw")) == pytest.approx(before + 0.5, abs=1e-3),
             timeout=2, what="ALMemory catching up")


def test_added_delay_is_felt_per_call(endpoint):
    _, session = endpoint(delay_ms=20)
    memory = session.service("ALMemory")
    started = time.monotonic()
    for _ in range(5):
        memory.getData("DCM/CycleTime")
    assert time.monotonic() - started >= 0.1


def test_as_a_node_and_bad_options(net):
    node = net.start(NaoqiSim(FakeNaoqiConfig(listen=f"tcp://127.0.0.1:{free_port()}"), name="fake"))
    session = qi.Session()
    session.connect(node.config.listen)
    try:
        assert session.service("ALRobotPosture").goToPosture("Crouch", 1.0) is True
    finally:
        session.close()
    with pytest.raises(ConfigError, match="listen"):
        FakeNaoqiConfig(listen="127.0.0.1:9559")
    with pytest.raises(ConfigError, match="model"):
        FakeNaoqiConfig(model="asimo")


def test_speech_keys_can_appear_only_with_the_first_speech(endpoint):
    _fake, session = endpoint(speech_keys="after-first-say")
    memory = session.service("ALMemory")
    with pytest.raises(RuntimeError, match="key not found"):
        memory.getListData(["ALTextToSpeech/TextStarted", "ALTextToSpeech/TextDone"])
    session.service("ALTextToSpeech").say("hi")  # returns once spoken
    assert memory.getListData(["ALTextToSpeech/TextStarted", "ALTextToSpeech/TextDone"]) == [0, 1]


def test_a_frozen_robot_keeps_its_socket_and_answers_nothing_until_resumed(endpoint):
    fake, session = endpoint(freeze_after_s=0.3)
    memory = session.service("ALMemory")
    assert memory.getData("DCM/CycleTime") == 10
    wait_for(lambda: not fake.answering.is_set(), what="the robot to freeze by itself")
    pending = memory.getData("DCM/CycleTime", _async=True)
    assert pending.wait(300) == qi.FutureState.Running and session.isConnected()
    fake.resume()
    assert pending.value(2000) == 10
    fake.freeze()
    assert not memory.getData("DCM/CycleTime", _async=True).isFinished()
    assert FakeNaoqiConfig(freeze_after_s=0).freeze_after_s == 0
    with pytest.raises(ConfigError, match="freeze_after_s"):
        FakeNaoqiConfig(freeze_after_s=-1)
