"""The command path against the simulator over real Zenoh sessions: the robot on
one session, the client on another (two machines of one loopback network).

Every verb round-trips; every bad request gets a typed error reply that names
what is wrong and moves nothing; every command is announced on
``<robot>/events/command``; everything on the bus fits its JSON Schema.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import pytest

from sonibus import schemas
from sonibus.adapters.sim import SimRobot
from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import Bus, CommandError, RobotNotFound, decode, load_model, robot_info, send_command
from sonibus.bus.verbs import METHODS, RobotVerbs, missing

from .conftest import wait_for

RATE_HZ = 50
PERIOD = 1.0 / RATE_HZ
WPM = 600  # fast speech (0.1 s a word) keeps the speech tests short

NOD = "animations/Stand/Gestures/Yes_1"       # 1.7 s, HeadPitch only
SKY = "animations/Stand/Gestures/ShowSky_1"   # 3.0 s, head and right arm

# Every request the tests below send expecting success (checked against the
# request schemas by test_valid_requests_fit_their_schema).
R: dict[str, tuple[str, dict[str, Any]]] = {
    "list": ("behavior/list", {}),
    "run_nod": ("behavior/run", {"name": NOD}),
    "run_sky": ("behavior/run", {"name": SKY}),
    "stop_sky": ("behavior/stop", {"name": SKY}),
    "stop_any": ("behavior/stop", {}),
    "head_away": ("joints/set", {"names": ["HeadYaw", "HeadPitch"], "angles": [0.6, 0.3], "speed": 1.0}),
    "head_arm": ("joints/set", {"names": ["HeadYaw", "LShoulderPitch"], "angles": [0.5, 0.4], "speed": 1.0}),
    "head_slow": ("joints/set", {"names": ["HeadYaw"], "angles": [2.0], "speed": 0.1}),
    "head_default_speed": ("joints/set", {"names": ["HeadYaw"], "angles": [-0.4]}),
    "posture_Stand": ("posture", {"name": "Stand", "speed": 0.8}),
    "posture_StandInit": ("posture", {"name": "StandInit", "speed": 0.8}),
    "posture_Crouch": ("posture", {"name": "Crouch", "speed": 0.8}),
    "posture_Sit": ("posture", {"name": "Sit", "speed": 0.8}),
    "posture_default_speed": ("posture", {"name": "Crouch"}),
    "say_short": ("say", {"text": "Hi."}),
    "say_medium": ("say", {"text": "Hello there, how are you today?"}),
    "say_long": ("say", {"text": "This is a much longer sentence that the robot needs quite a bit more time "
                                 "to speak out loud than the two before it."}),
    "say_slow": ("say", {"text": "Hello there, how are you today?", "speed": 50, "volume": 0.5}),
    "say_first": ("say", {"text": "one two three four five six seven eight nine ten"}),
    "say_queued_1": ("say", {"text": "queued words"}),
    "say_queued_2": ("say", {"text": "also queued"}),
    "say_marker": ("say", {"text": "marker"}),
    "limp_head_yaw": ("stiffness", {"names": ["HeadYaw"], "value": 0.0}),
    "stiff_head_yaw": ("stiffness", {"names": ["HeadYaw"], "value": 1.0}),
    "stiff_rarm": ("stiffness", {"names": ["RArm"], "value": 1.0}),
    "stiff_body": ("stiffness", {"names": ["Body"], "value": 1.0}),
    "awareness_on": ("awareness", {"enabled": True}),
    "awareness_off": ("awareness", {"enabled": False}),
    "stop": ("stop", {}),
}


# -- helpers --------------------------------------------------------------------

class Stream:
    """What a subscription delivers, decoded: every sample in arrival order and
    the latest value per key."""

    def __init__(self, bus: Bus, keyexpr: str) -> None:
        self.subscriber, self.queue = bus.subscribe(keyexpr, maxlen=1_000_000)
        self.samples: list[tuple[str, dict[str, Any]]] = []
        self.latest: dict[str, dict[str, Any]] = {}

    def poll(self) -> dict[str, dict[str, Any]]:
        """Drain the queue; the latest decoded value per key."""
        while (item := self.queue.get(timeout=0)) is not None:
            key, payload = item
            message = decode(payload)
            self.samples.append((key, message))
            self.latest[key] = message
            self._add(key, message)
        return self.latest

    def _add(self, key: str, message: dict[str, Any]) -> None:
        pass


class Joints(Stream):
    """``<robot>/joints/*`` reassembled into frames by ``seq``."""

    def __init__(self, bus: Bus, robot: str) -> None:
        super().__init__(bus, f"{robot}/joints/*")
        self.prefix = f"{robot}/joints/"
        self.names = load_model(robot.rstrip("0123456789")).joint_names
        self.by_seq: dict[int, dict[str, float]] = {}
        self.t: dict[int, float] = {}

    def _add(self, key: str, message: dict[str, Any]) -> None:
        self.by_seq.setdefault(message["seq"], {})[key.removeprefix(self.prefix)] = message["v"]
        self.t[message["seq"]] = message["t"]

    def complete(self, after: int = -1) -> list[tuple[int, dict[str, float]]]:
        """Frames holding every joint, by ``seq``, newer than ``after``."""
        self.poll()
        return [(s, f) for s, f in sorted(self.by_seq.items()) if s > after and len(f) == len(self.names)]

    def last(self) -> tuple[int, dict[str, float]]:
        return wait_for(lambda: self.complete()[-1:], what="a complete frame")[0]

    def next(self, count: int, timeout: float = 5.0) -> list[tuple[int, dict[str, float]]]:
        """The next ``count`` complete frames from now."""
        after = self.last()[0]

        def ready() -> list[tuple[int, dict[str, float]]] | None:
            frames = self.complete(after)
            return frames[:count] if len(frames) >= count else None

        return wait_for(ready, timeout, f"{count} new frames")

    def wait_pose(self, pose: dict[str, float], timeout: float = 5.0, tol: float = 1e-9) -> dict[str, float]:
        def there() -> dict[str, float] | None:
            frame = self.last()[1]
            return frame if all(abs(frame[j] - v) <= tol for j, v in pose.items()) else None

        return wait_for(there, timeout, f"pose {pose}")


class Events(Stream):
    def find(self, kind: str | None = None, **fields: Any) -> list[dict[str, Any]]:
        self.poll()
        return [m for _, m in self.samples if kind in (None, m.get("kind"))
                and all(m.get(f) == v for f, v in fields.items())]

    def wait(self, kind: str, timeout: float = 5.0, **fields: Any) -> dict[str, Any]:
        return wait_for(lambda: self.find(kind, **fields), timeout, f"'{kind}' event {fields}")[0]


@dataclass
class Rig:
    """A simulated robot and a client on another session watching it."""

    name: str
    sim: SimRobot
    bus: Bus
    joints: Joints
    events: Events


def connect(net: Any, robot: str = "pepper") -> Rig:
    sim = net.sim(robot, rate_hz=RATE_HZ, idle=False, words_per_minute=WPM)
    client = net.bus(f"client-{robot}")
    # Declared before the joints: once joint samples arrive, the event
    # subscription (sent earlier on the same link) is in place too.
    events = Events(client, f"{robot}/events/*")
    joints = Joints(client, robot)
    wait_for(joints.complete, what=f"a complete frame from {robot}")
    return Rig(robot, sim, client, joints, events)


@pytest.fixture
def pepper(net: Any) -> Rig:
    return connect(net, "pepper")


def ok(rig: Rig, verb: str, args: dict[str, Any] | None = None, timeout: float = 5.0) -> dict[str, Any]:
    """Send a request meant to succeed (checked against its schema first)."""
    schemas.validate("cmd/" + verb, args or {})
    return send_command(rig.bus, rig.name, verb, args, timeout)


def refused(rig: Rig, verb: str, args: Any) -> CommandError:
    with pytest.raises(CommandError) as caught:
        send_command(rig.bus, rig.name, verb, args, timeout=5.0)
    assert type(caught.value) is CommandError, f"expected a refusal, got {caught.value!r}"
    return caught.value


def assert_still(rig: Rig, reference: dict[str, float], count: int = 6) -> None:
    """The next ``count`` frames are exactly ``reference``."""
    for seq, frame in rig.joints.next(count):
        moved = {j: (reference[j], v) for j, v in frame.items() if v != reference[j]}
        assert not moved, f"frame {seq}: joints moved (before, now): {moved}"


def assert_frozen(rig: Rig, count: int = 6) -> dict[str, float]:
    """Motion has stopped: after a frame that may still be in flight, frames stay identical."""
    reference = rig.joints.next(2)[-1][1]
    assert_still(rig, reference, count)
    return reference


def wait_moving(rig: Rig, joint: str, start: float, by: float = 0.05) -> float:
    def moved() -> float | None:
        v = rig.joints.last()[1][joint]
        return v if abs(v - start) >= by else None

    return wait_for(moved, 5.0, f"{joint} to move {by} from {start}")


# -- every verb round-trips -------------------------------------------------------

def test_behavior_list(pepper):
    result = ok(pepper, *R["list"])
    assert result == {"behaviors": sorted(LIBRARY)}
    assert len(result["behaviors"]) >= 6
    assert robot_info(pepper.bus, "pepper")["behaviors"] == result["behaviors"]


def test_behavior_run_replies_at_start_and_announces_stopped(pepper):
    _, before = pepper.joints.last()
    result = ok(pepper, *R["run_nod"])
    assert result["name"] == NOD
    assert result["duration"] == pytest.approx(LIBRARY[NOD].duration)
    started = pepper.events.wait("behavior", name=NOD, state="started")
    stopped = pepper.events.wait("behavior", timeout=LIBRARY[NOD].duration + 3, name=NOD, state="stopped")
    assert stopped["end"] == "finished"  # (issue 37, item 9: a cut one read "stopped" alike)
    # not before its duration (a frame late on a busy machine ends it later: the wait bounds that)
    assert stopped["t"] - started["t"] >= LIBRARY[NOD].duration - 0.2
    during = [f for s, f in pepper.joints.complete() if started["t"] <= pepper.joints.t[s] <= stopped["t"]]
    pitches = [f["HeadPitch"] for f in during]
    assert max(pitches) - min(pitches) > 0.2, "the behavior did not visibly move the head"
    # a behavior returns to where it started
    pepper.joints.wait_pose(before, timeout=5.0, tol=1e-6)
    states = [e["state"] for e in pepper.events.find("behavior")]
    assert states == ["started", "stopped"]


def test_behavior_run_while_it_runs_is_refused(pepper):
    ok(pepper, *R["run_nod"])
    error = refused(pepper, "behavior/run", {"name": NOD})
    assert error.code == "failed"
    assert NOD in error.message
    ok(pepper, *R["stop"])


@pytest.mark.parametrize("request_name", ["stop_sky", "stop_any"])
def test_behavior_stop_interrupts(pepper, request_name):
    _, before = pepper.joints.last()
    ok(pepper, *R["run_sky"])
    started = pepper.events.wait("behavior", name=SKY, state="started")
    wait_moving(pepper, "RShoulderPitch", before["RShoulderPitch"], by=0.1)
    assert ok(pepper, *R[request_name]) == {"was_running": True}
    stopped = pepper.events.wait("behavior", timeout=5.0, name=SKY, state="stopped")
    assert stopped["t"] - started["t"] < LIBRARY[SKY].duration  # cut before its end (at its end it is back home)
    assert stopped["end"] == "cut"
    frozen = assert_frozen(pepper)
    assert frozen["RShoulderPitch"] != before["RShoulderPitch"], "stopped where it started: no interruption seen"
    assert ok(pepper, *R[request_name]) == {"was_running": False}
    assert len(pepper.events.find("behavior", state="stopped")) == 1


def test_joints_set_moves_the_joints(pepper):
    names, angles = R["head_arm"][1]["names"], R["head_arm"][1]["angles"]
    assert ok(pepper, *R["head_arm"])["targets"] == dict(zip(names, angles, strict=True))  # (issue 37: it was {})
    reached = pepper.joints.wait_pose(dict(zip(names, angles, strict=True)), timeout=5.0)
    assert_still(pepper, reached)
    ok(pepper, *R["head_default_speed"])
    pepper.joints.wait_pose({"HeadYaw": -0.4}, timeout=5.0)


@pytest.mark.parametrize(("robot", "posture"), [("pepper", "Stand"), ("pepper", "StandInit"),
                                                 ("pepper", "Crouch"), ("nao", "Sit")])
def test_posture(net, robot, posture):
    rig = connect(net, robot)
    model = load_model(robot)
    ok(rig, *R["head_away"])  # start away from every posture
    rig.joints.wait_pose({"HeadYaw": 0.6, "HeadPitch": 0.3}, timeout=5.0)
    assert ok(rig, *R[f"posture_{posture}"]) == {"name": posture}
    reached = rig.events.wait("posture", timeout=5.0, name=posture, state="reached")
    states = [e["state"] for e in rig.events.find("posture", name=posture)]
    assert states == ["started", "reached"]
    target = model.posture(posture)
    assert set(target) == set(model.joint_names)
    frames = [f for s, f in rig.joints.complete() if rig.joints.t[s] >= reached["t"]]
    frames += [f for _, f in rig.joints.next(3)]
    for frame in frames:
        off = {j: (target[j], v) for j, v in frame.items() if abs(v - target[j]) > 1e-9}
        assert not off, f"'reached' announced but joints are not in {posture}: {off}"


def test_posture_default_speed_and_interruption(pepper):
    ok(pepper, *R["posture_default_speed"])
    pepper.events.wait("posture", name="Crouch", state="started")
    ok(pepper, *R["head_away"])
    pepper.events.wait("posture", name="Crouch", state="interrupted")
    pepper.joints.wait_pose({"HeadYaw": 0.6, "HeadPitch": 0.3}, timeout=5.0)
    assert not pepper.events.find("posture", state="reached")


def test_behavior_interrupts_a_posture_and_says_so(pepper):
    ok(pepper, *R["posture_default_speed"])  # about 1.2 s to Crouch
    pepper.events.wait("posture", name="Crouch", state="started")
    ok(pepper, *R["run_nod"])
    pepper.events.wait("behavior", name=NOD, state="started")
    pepper.events.wait("posture", timeout=3.0, name="Crouch", state="interrupted")
    ok(pepper, *R["stop"])


def test_say_announces_speech_and_duration_grows_with_text(pepper):
    durations = [ok(pepper, *R[name])["duration"] for name in ("say_short", "say_medium", "say_long")]
    assert 0 < durations[0] < durations[1] < durations[2]
    slow = ok(pepper, *R["say_slow"])
    assert slow["duration"] > durations[1]
    assert slow["queued"] == 3
    text = R["say_short"][1]["text"]
    started = pepper.events.wait("speech", text=text, state="started")
    done = pepper.events.wait("speech", timeout=3.0, text=text, state="done")
    assert done["t"] - started["t"] >= durations[0] - 3 * PERIOD - 0.1  # spoken for its duration at least
    medium = R["say_medium"][1]["text"]
    second = pepper.events.wait("speech", timeout=3.0, text=medium, state="started")
    assert second["t"] >= done["t"], "the second text started before the first was done"
    ok(pepper, *R["stop"])


def test_stiffness_zero_holds_a_joint(pepper):
    _, before = pepper.joints.last()
    assert ok(pepper, *R["limp_head_yaw"]) == {"joints": ["HeadYaw"]}
    ok(pepper, *R["head_away"])
    frame = pepper.joints.wait_pose({"HeadPitch": 0.3}, timeout=5.0)  # the stiff joint moves ...
    assert frame["HeadYaw"] == before["HeadYaw"]                     # ... the limp one does not
    for _, frame in pepper.joints.next(5):
        assert frame["HeadYaw"] == before["HeadYaw"]
    assert ok(pepper, *R["stiff_head_yaw"]) == {"joints": ["HeadYaw"]}
    ok(pepper, *R["head_away"])
    pepper.joints.wait_pose({"HeadYaw": 0.6}, timeout=5.0)


def test_stiffness_chains_and_body(pepper):
    model = load_model("pepper")
    assert ok(pepper, *R["stiff_rarm"]) == {"joints": list(model.chain("RArm"))}
    assert sorted(ok(pepper, *R["stiff_body"])["joints"]) == sorted(model.joint_names)


def test_awareness(pepper):
    assert robot_info(pepper.bus, "pepper")["awareness"] is False  # (the info says it: issue 29, item 3)
    assert ok(pepper, *R["awareness_on"]) == {"enabled": True, "previous": False}
    assert robot_info(pepper.bus, "pepper")["awareness"] is True
    assert ok(pepper, *R["awareness_off"]) == {"enabled": False, "previous": True}
    assert robot_info(pepper.bus, "pepper")["awareness"] is False


def test_stop_halts_a_running_behavior(pepper):
    _, before = pepper.joints.last()
    ok(pepper, *R["run_sky"])
    started = pepper.events.wait("behavior", name=SKY, state="started")
    wait_moving(pepper, "RShoulderPitch", before["RShoulderPitch"], by=0.1)
    assert ok(pepper, *R["stop"]) == {"held": True, "cut": [SKY], "silenced": 0}  # (issue 37: it was {})
    stopped = pepper.events.wait("behavior", timeout=5.0, name=SKY, state="stopped")
    assert stopped["t"] - started["t"] < LIBRARY[SKY].duration  # cut before its end (at its end it is back home)
    assert stopped["end"] == "cut"
    frozen = assert_frozen(pepper)
    assert frozen["RShoulderPitch"] != before["RShoulderPitch"]


def test_stop_halts_joints_set_midway(pepper):
    _, before = pepper.joints.last()
    ok(pepper, *R["head_slow"])  # 2 rad at 0.1 * 7.34 rad/s: about 2.7 s
    wait_moving(pepper, "HeadYaw", before["HeadYaw"], by=0.2)
    ok(pepper, *R["stop"])
    frozen = assert_frozen(pepper, count=10)
    assert before["HeadYaw"] + 0.2 <= frozen["HeadYaw"] < 1.5, f"HeadYaw stopped at {frozen['HeadYaw']}"


def test_stop_clears_queued_speech(pepper):
    first = R["say_first"][1]["text"]
    duration = ok(pepper, *R["say_first"])["duration"]
    assert ok(pepper, *R["say_queued_1"])["queued"] == 1
    assert ok(pepper, *R["say_queued_2"])["queued"] == 2
    started = pepper.events.wait("speech", text=first, state="started")
    ok(pepper, *R["stop"])
    done = pepper.events.wait("speech", timeout=5.0, text=first, state="done")
    assert done["t"] - started["t"] < duration, "stop did not cut the current speech"
    # A text said after the stop is spoken next: nothing queued before the stop comes first.
    assert ok(pepper, *R["say_marker"])["queued"] == 0
    pepper.events.wait("speech", timeout=3.0, text="marker", state="done")
    spoken = [e["text"] for e in pepper.events.find("speech", state="started")]
    assert spoken == [first, "marker"]


@pytest.mark.parametrize("garbage", [
    {"now": True, "why": ["because", 1.5]},
    {"speed": math.nan, "names": "everything"},
    [1, 2, 3],
    "halt!",
], ids=["unknown-keys", "nan-and-wrong-types", "list-payload", "string-payload"])
def test_stop_runs_whatever_its_arguments(pepper, garbage):
    _, before = pepper.joints.last()
    ok(pepper, *R["head_slow"])
    wait_moving(pepper, "HeadYaw", before["HeadYaw"], by=0.1)
    assert send_command(pepper.bus, "pepper", "stop", garbage)["held"] is True
    frozen = assert_frozen(pepper)
    assert frozen["HeadYaw"] < 1.5


def test_unowned_robot_is_not_found_promptly(pepper):
    started = time.monotonic()
    with pytest.raises(RobotNotFound) as caught:
        send_command(pepper.bus, "ghost", "say", {"text": "hello"}, timeout=5.0)
    assert time.monotonic() - started < 5.0  # not waited out: a query as long as its timeout is a 'timeout'
    assert caught.value.code == "robot_not_found"
    assert "ghost" in str(caught.value)
    assert robot_info(pepper.bus, "ghost") is None


def test_stopped_robot_is_not_found(pepper):
    pepper.sim.stop()

    def not_found() -> bool:
        started = time.monotonic()
        try:
            send_command(pepper.bus, "pepper", "stop", timeout=2.0)
        except RobotNotFound:
            return time.monotonic() - started < 2.0  # (not its timeout: that would be code 'timeout')
        return False

    wait_for(not_found, 3.0, "RobotNotFound for a robot whose owner stopped")


# -- bad requests: a typed error, a message naming the bad value, nothing moves ---

NAN = math.nan
BAD: list[tuple[str, str, Any, str, list[str]]] = [
    # id, verb, arguments, code, what the message must name
    ("unknown-joint", "joints/set", {"names": ["HeadYaw", "HeadYawn"], "angles": [1.0, 0.0]},
     "unknown_joint", ["HeadYawn"]),
    ("nan-angle", "joints/set", {"names": ["HeadYaw", "HeadPitch"], "angles": [1.0, NAN]}, "bad_request", ["nan"]),
    ("inf-angle", "joints/set", {"names": ["HeadYaw"], "angles": [math.inf]}, "bad_request", ["inf"]),
    ("nan-speed", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": NAN}, "bad_request",
     ["speed", "nan"]),
    ("angle-outside-limits", "joints/set", {"names": ["HeadYaw", "HeadPitch"], "angles": [1.0, 1.2]},
     "out_of_range", ["HeadPitch", "1.2", "-0.706858", "0.637045"]),
    # issue 37, item 5: an angle meant in degrees is said so
    ("degrees", "joints/set", {"names": ["HeadYaw"], "angles": [45.0], "speed": 0.2}, "out_of_range",
     ["HeadYaw = 45.0 is outside its limits [-2.08567, 2.08567] rad", "(45° = 0.785398 rad: sonibus takes radians)"]),
    ("speed-0", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 0}, "out_of_range", ["speed", "0"]),
    ("speed-1.5", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 1.5}, "out_of_range",
     ["speed", "1.5"]),
    ("names-angles-mismatch", "joints/set", {"names": ["HeadYaw", "HeadPitch"], "angles": [1.0]}, "bad_request",
     ["2 names", "1 angle"]),
    ("extra-argument", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "sped": 0.5}, "bad_request", ["sped"]),
    ("non-map-payload", "joints/set", [["HeadYaw"], [1.0]], "bad_request", ["map"]),
    ("string-payload", "posture", "Crouch", "bad_request", ["map"]),
    ("unknown-behavior", "behavior/run", {"name": "animations/Stand/Gestures/Fly_1"}, "unknown_behavior",
     ["animations/Stand/Gestures/Fly_1"]),
    ("stop-unknown-behavior", "behavior/stop", {"name": "animations/Nope_9"}, "unknown_behavior", ["Nope_9"]),
    ("unknown-posture", "posture", {"name": "Sit"}, "unknown_posture", ["Sit"]),  # NAO's, not Pepper's
    ("nan-posture-speed", "posture", {"name": "Crouch", "speed": NAN}, "bad_request", ["speed", "nan"]),
    ("empty-text", "say", {"text": ""}, "bad_request", ["text"]),
    ("blank-text", "say", {"text": " \t  "}, "bad_request", ["text"]),
    ("text-501-chars", "say", {"text": "x" * 501}, "bad_request", ["text"]),
    ("say-volume-2", "say", {"text": "hello", "volume": 2}, "out_of_range", ["volume", "2"]),
    ("stiffness-unknown-joint", "stiffness", {"names": ["Tail"], "value": 0.0}, "unknown_joint", ["Tail"]),
    ("stiffness-1.5", "stiffness", {"names": ["Body"], "value": 1.5}, "out_of_range", ["value", "1.5"]),
    ("awareness-not-bool", "awareness", {"enabled": "yes"}, "bad_request", ["enabled", "yes"]),
    ("unknown-verb", "fly", {"to": "the moon"}, "unknown_verb", ["fly"]),
]


@pytest.mark.parametrize(("verb", "args", "code", "names"), [case[1:] for case in BAD], ids=[c[0] for c in BAD])
def test_bad_request_is_refused_and_moves_nothing(pepper, verb, args, code, names):
    _, before = pepper.joints.last()
    error = refused(pepper, verb, args)
    assert error.code == code, f"code {error.code!r} ({error.message})"
    assert error.message and "\n" not in error.message
    for name in names:
        assert name.lower() in error.message.lower(), f"{name!r} not named in {error.message!r}"
    assert_still(pepper, before)
    if verb in schemas.command_verbs():
        event = pepper.events.wait("command", verb=verb, ok=False)
        assert event["error"] == error.message
    happened = [e for e in pepper.events.find() if e["kind"] != "command"]
    assert not happened, f"a refused request had effects: {happened}"


def test_refused_request_does_not_interrupt_a_running_behavior(pepper):
    ok(pepper, *R["run_nod"])
    started = pepper.events.wait("behavior", name=NOD, state="started")
    refused(pepper, "joints/set", {"names": ["HeadYaw"], "angles": [9.0]})
    refused(pepper, "posture", {"name": "Sit"})
    stopped = pepper.events.wait("behavior", timeout=LIBRARY[NOD].duration + 3, name=NOD, state="stopped")
    assert stopped["t"] - started["t"] >= LIBRARY[NOD].duration - 0.2  # ran to its end, not cut short


# -- the command event ------------------------------------------------------------

def test_every_command_is_announced(pepper):
    sequence = [*(R[n] for n in ("list", "awareness_on", "stiff_body", "head_away", "say_short",
                                 "posture_Crouch", "run_nod", "stop_any", "stop")),
                ("joints/set", {"names": ["Nose"], "angles": [0.0]}),
                ("say", {"text": ""})]
    for index, (verb, args) in enumerate(sequence):
        try:
            send_command(pepper.bus, "pepper", verb, args)
            error = None
        except CommandError as exc:
            error = exc.message
        events = wait_for(lambda n=index + 1: (e := pepper.events.find("command"))[n - 1:] and e,
                          5.0, f"command event for {verb}")
        event = events[index]
        assert (event["verb"], event["args"], event["ok"]) == (verb, args, error is None), event
        assert event.get("error") == error
    assert len(pepper.events.find("command")) == len(sequence)


# -- everything on the bus fits its schema ---------------------------------------

def test_joint_samples_fit_the_schema(pepper):
    ok(pepper, *R["run_nod"])
    pepper.joints.next(25)
    samples = [m for _, m in pepper.joints.samples]
    assert len(samples) >= 25 * 17
    for message in samples:
        schemas.validate("joint_sample", message)
    assert len({m["v"] for m in samples}) > 17, "no motion was sampled"


def test_events_fit_the_schema(pepper):
    ok(pepper, *R["run_nod"])
    pepper.events.wait("behavior", name=NOD, state="started")
    ok(pepper, *R["posture_Crouch"])                       # interrupts the behavior
    ok(pepper, *R["head_away"])                            # interrupts the posture
    ok(pepper, *R["posture_StandInit"])
    pepper.events.wait("posture", timeout=5.0, name="StandInit", state="reached")
    ok(pepper, *R["say_short"])
    pepper.events.wait("speech", timeout=3.0, state="done")
    ok(pepper, *R["say_medium"])
    pepper.events.wait("speech", text=R["say_medium"][1]["text"], state="started")
    ok(pepper, *R["stop"])                                 # ends the speech
    refused(pepper, "say", {"text": ""})
    refused(pepper, "say", [1])
    wait_for(lambda: len(pepper.events.find("command")) == 9, what="9 command events")
    events = pepper.events.find()
    for event in events:
        schemas.validate("event", event)
    seen = {(e["kind"], e.get("state")) for e in events}
    assert {("behavior", "started"), ("behavior", "stopped"), ("posture", "started"), ("posture", "reached"),
            ("posture", "interrupted"), ("speech", "started"), ("speech", "done")} <= seen
    assert {e["ok"] for e in events if e["kind"] == "command"} == {True, False}


@pytest.mark.parametrize("robot", ["pepper", "nao"])
def test_robot_info_fits_the_schema(net, robot):
    rig = connect(net, robot)
    info = robot_info(rig.bus, robot)
    schemas.validate("robot_info", info)
    model = load_model(robot)
    assert info["robot"] == robot
    assert info["model"] == robot
    assert [j["name"] for j in info["joints"]] == list(model.joint_names)
    assert set(rig.joints.complete()[-1][1]) == {j["name"] for j in info["joints"]}
    for joint in info["joints"]:
        assert joint["min"] < joint["max"], joint
    assert info["rate_hz"] == RATE_HZ
    assert info["behaviors"] == sorted(LIBRARY)
    assert set(info["postures"]) == set(model.postures)
    assert info["schema_version"] == schemas.VERSION
    assert info["owner"]["node"] == f"sim-{robot}"


def test_replies_fit_the_schema(pepper):
    def ask(verb: str, args: Any) -> dict[str, Any]:
        replies = pepper.bus.query(f"pepper/cmd/{verb}", args)
        assert len(replies) == 1, replies
        schemas.validate("command_reply", replies[0])
        assert replies[0]["verb"] == verb
        return replies[0]

    for verb in schemas.command_verbs():
        example = next(args for v, args in R.values() if v == verb)
        reply = ask(verb, example)
        assert reply["ok"] is True, reply
    ask("stop", {})
    errors = {
        "bad_request": ("say", {"text": ""}),
        "unknown_verb": ("fly", {}),
        "unknown_joint": ("joints/set", {"names": ["Nose"], "angles": [0.0]}),
        "out_of_range": ("joints/set", {"names": ["HeadYaw"], "angles": [9.0]}),
        "unknown_behavior": ("behavior/run", {"name": "animations/Nope"}),
        "unknown_posture": ("posture", {"name": "Sit"}),
    }
    ok(pepper, *R["run_nod"])
    errors["failed"] = ("behavior/run", {"name": NOD})
    for code, (verb, args) in errors.items():
        reply = ask(verb, args)
        assert reply["ok"] is False
        assert reply["error"]["code"] == code, reply


@pytest.mark.parametrize("name", sorted(R))
def test_valid_requests_fit_their_schema(name):
    verb, args = R[name]
    schemas.validate("cmd/" + verb, args)


def test_every_verb_has_a_hook_and_every_hook_a_verb():
    verbs = schemas.command_verbs()
    assert set(verbs) == {"behavior/run", "behavior/stop", "behavior/list", "joints/set", "posture", "say",
                          "stiffness", "awareness", "stop"}
    hooks = set(METHODS.values())  # the verbs a robot's Verbs class implements (bus/verbs.py)
    assert hooks == {verb.replace("/", "_") for verb in verbs}
    assert missing(SimRobot.Verbs) == []
    for verb in verbs:
        hook = getattr(SimRobot.Verbs, METHODS[verb])
        assert callable(hook)
        assert hook is not getattr(RobotVerbs, hook.__name__, None), f"{verb}: no simulator hook"
    assert {v for v, _ in R.values()} == set(verbs), "a verb is never exercised with a valid request"
