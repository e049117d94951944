"""The command contract, run against both robots that serve it: the simulator
and the NAOqi adapter (on the fake NAOqi endpoint). Same verbs, same reply keys
where docs/design.md says so, same error codes, nothing moved by a refusal.

Documented differences (docs/naoqi.md): NAOqi's ``behavior/run`` and ``say``
replies have no ``duration`` (the robot does not tell it)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from sonibus import schemas
from sonibus.adapters.naoqi import NaoqiRobot
from sonibus.adapters.sim import SimRobot
from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import CommandError, load_model, send_command
from sonibus.bus.verbs import missing

from ..test_commands import assert_still, connect
from .conftest import attach

NOD = "animations/Stand/Gestures/Yes_1"
RARM = list(load_model("pepper").chain("RArm"))

# verb, arguments, the reply (exact), or the keys it must have at least (a set)
OK: list[tuple[str, dict[str, Any], dict[str, Any] | set[str]]] = [
    ("behavior/list", {}, {"behaviors": sorted(LIBRARY)}),
    ("behavior/run", {"name": NOD}, {"name"}),
    ("behavior/stop", {"name": NOD}, {"was_running": True}),
    ("behavior/stop", {}, {"was_running": False}),
    ("joints/set", {"names": ["HeadYaw", "HeadPitch"], "angles": [0.3, 0.1], "speed": 0.5},
     {"targets": {"HeadYaw": 0.3, "HeadPitch": 0.1}, "speed": 0.5}),  # (issue 37: what it did; it was {})
    ("posture", {"name": "Crouch", "speed": 0.2}, {"name": "Crouch"}),  # still going at the stop
    ("say", {"text": "Hi.", "speed": 400}, {"queued"}),
    ("stiffness", {"names": ["RArm"], "value": 0.9}, {"joints": RARM}),
    ("awareness", {"enabled": True}, {"enabled": True, "previous": False}),
    ("awareness", {"enabled": False}, {"enabled": False, "previous": True}),
    ("stop", {}, {"held", "cut"}),
]

BAD: list[tuple[str, str, Any, str, str]] = [
    # id, verb, arguments, code, what the message names
    ("unknown-joint", "joints/set", {"names": ["HeadYawn"], "angles": [0.0]}, "unknown_joint", "HeadYawn"),
    ("nan", "joints/set", {"names": ["HeadYaw"], "angles": [math.nan]}, "bad_request", "nan"),
    ("out-of-limits", "joints/set", {"names": ["HeadPitch"], "angles": [1.2]}, "out_of_range", "HeadPitch"),
    ("speed-0", "joints/set", {"names": ["HeadYaw"], "angles": [0.1], "speed": 0}, "out_of_range", "speed"),
    ("speed-1.5", "joints/set", {"names": ["HeadYaw"], "angles": [0.1], "speed": 1.5}, "out_of_range", "1.5"),
    ("unknown-behavior", "behavior/run", {"name": "animations/Fly_1"}, "unknown_behavior", "Fly_1"),
    ("unknown-posture", "posture", {"name": "Sit"}, "unknown_posture", "Sit"),
    ("empty-text", "say", {"text": ""}, "bad_request", "text"),
    ("overlong-text", "say", {"text": "x" * 501}, "bad_request", "501"),
    ("unknown-verb", "fly", {"to": "the moon"}, "unknown_verb", "fly"),
]


@pytest.fixture(params=["sim", "naoqi"])
def robot(request, fakes, net):
    """The same robot, ``pepper``, served by the simulator or by the NAOqi adapter."""
    if request.param == "sim":
        return connect(net, "pepper")
    fake = fakes()
    return attach(net, fake.url, fake=fake)


def test_every_verb_answers_with_the_documented_reply(robot):
    for verb, args, expected in OK:
        schemas.validate("cmd/" + verb, args)
        result = send_command(robot.bus, "pepper", verb, args)
        if isinstance(expected, set):
            assert expected <= set(result), (verb, result)
        else:
            assert result == expected, verb
        if verb == "behavior/run":
            robot.events.wait("behavior", name=NOD, state="started")
    robot.events.wait("posture", name="Crouch", state="interrupted")  # by the stop


def test_running_a_running_behavior_fails(robot):
    send_command(robot.bus, "pepper", "behavior/run", {"name": NOD})
    with pytest.raises(CommandError) as failed:
        send_command(robot.bus, "pepper", "behavior/run", {"name": NOD})
    assert failed.value.code == "failed" and NOD in failed.value.message
    assert send_command(robot.bus, "pepper", "stop", {})["held"] is True


@pytest.mark.parametrize("garbage", [{"now": True}, [1, 2], "halt!"], ids=["unknown-keys", "list", "string"])
def test_stop_runs_whatever_its_arguments(robot, garbage):
    assert send_command(robot.bus, "pepper", "stop", garbage)["held"] is True


@pytest.mark.parametrize(("verb", "args", "code", "named"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_requests_get_the_same_error_and_move_nothing(robot, verb, args, code, named):
    _, before = robot.joints.last()
    with pytest.raises(CommandError) as refused:
        send_command(robot.bus, "pepper", verb, args)
    assert refused.value.code == code, refused.value.message
    assert named.lower() in refused.value.message.lower() and "\n" not in refused.value.message
    assert_still(robot, before)
    if verb in schemas.command_verbs():
        assert robot.events.wait("command", verb=verb, ok=False)["error"] == refused.value.message
    assert not [e for e in robot.events.find() if e["kind"] not in ("command", "connection", "status")]


def test_both_robots_have_a_hook_for_every_verb():
    hooks = {verb.replace("/", "_") for verb in schemas.command_verbs()}
    for adapter in (SimRobot, NaoqiRobot):  # the verbs are methods of its Verbs class (bus/verbs.py)
        assert {name for name in hooks if callable(getattr(adapter.Verbs, name, None))} == hooks, adapter.__name__
        assert missing(adapter.Verbs) == [], adapter.__name__
