"""Commands shaped once (bus/commands/shape.py): the same mistake gives the same error
from ``sonibus send`` (in-process, against a simulated Pepper on a real bus), from an
OSC datagram to a running gateway and from a JSON object; good commands give the same
request from all three."""

from __future__ import annotations

import io
import json
import socket

import pytest

from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import CommandError, codec, load_model
from sonibus.bus.cli import Environment, Exit, main
from sonibus.bus.commands import from_json, from_osc, from_words, validate

from .conftest import free_port, wait_for
from .osc.test_gateway import Client

# (verb, CLI words, OSC arguments, JSON object or None where a surface cannot say it, the error)
SHAPING = [
    ("say", ["hi", "volume=0.5", "speed=fast"], ["hi", 0.5, "fast"], {"text": "hi", "volume": 0.5, "speed": "fast"},
     "say: argument 3 (speed) must be a number, got string 'fast' — give a number, e.g. speed=225"),
    ("awareness", ["maybe"], ["maybe"], {"enabled": "maybe"},
     "awareness: argument 1 (enabled) must be T, F, 0 or 1, got string 'maybe'"),
    ("say", [], [], {}, "say: argument 1 (text) is missing — give a string"),
    ("posture", [], [], {}, "posture: argument 1 (name) is missing — give a string"),
    ("stiffness", ["names=Head"], ["Head"], {"names": ["Head"]},
     "stiffness: argument 2 (value) is missing — give a number, e.g. value=0.5"),
    ("joints/set", ["speed=0.5"], [0.5], {"speed": 0.5},
     "joints/set: argument 1 (names) is missing — give a list of strings"),
    ("joints/set", ["names=HeadYaw", "angles=0.3,zero"], None, {"names": ["HeadYaw"], "angles": [0.3, "zero"]},
     "joints/set: argument 2 (angles) item 2 must be a number, got string 'zero' — give a list of numbers, "
     "e.g. angles=[0.3,-0.1]"),
    ("say", ["hi", "volumes=3"], None, {"text": "hi", "volumes": 3},  # (a word with '=' and a name unlike
     "say has no argument 'volumes' — arguments: text, volume, speed"),  # any argument's is text: say 1+1=2)
    ("say", None, [3], {"text": 3}, "say: argument 1 (text) must be a string, got int 3"),
    ("stiffness", None, [True], {"names": True}, "stiffness: argument 1 (names) must be a list of strings, "
                                                   "got boolean true"),
]

# What shapes well but the robot refuses: its one message reaches every surface. An unknown
# verb is a usage mistake to ``sonibus send`` (exit 2, as the README's table says), refused
# (exit 4) otherwise.
ROBOT = [
    ("say", ["hi", "volume=2"], ["hi", 2.0], {"text": "hi", "volume": 2}, "out_of_range",
     "say: volume: 2.0 is greater than the maximum of 1"),
    ("posture", ["Sit"], ["Sit"], {"name": "Sit"}, "unknown_posture", "unknown posture 'Sit'"),
    ("dance", ["wildly"], ["wildly"], {"style": "wildly"}, "unknown_verb", "unknown command 'dance'"),
]

# (verb, CLI words, OSC arguments, JSON object, the request all three give)
GOOD = [
    ("say", ["good", "morning", "volume=1", "speed=120"], ["good", "morning", 1, 120],
     {"text": "good morning", "volume": 1, "speed": 120.0}, {"text": "good morning", "volume": 1.0, "speed": 120.0}),
    ("joints/set", ["names=HeadYaw,HeadPitch", "angles=[0.5,-0.1]", "speed=1"], ["HeadYaw", 0.5, "HeadPitch", -0.1, 1],
     {"names": ["HeadYaw", "HeadPitch"], "angles": [0.5, -0.1], "speed": 1},
     {"names": ["HeadYaw", "HeadPitch"], "angles": [0.5, -0.1], "speed": 1.0}),
    ("stiffness", ["names=Head,LArm", "value=0"], ["Head", "LArm", 0], {"names": ["Head", "LArm"], "value": 0},
     {"names": ["Head", "LArm"], "value": 0.0}),
    ("awareness", ["off"], [0], {"enabled": False}, {"enabled": False}),
    ("awareness", ["T"], [True], {"enabled": 1}, {"enabled": True}),
    ("posture", ["Crouch", "speed=0.5"], ["Crouch", 0.5], {"name": "Crouch", "speed": 0.5},
     {"name": "Crouch", "speed": 0.5}),
    ("behavior/stop", [], [], {}, {}),
    ("stop", ["now"], [1.0], {"why": "button"}, {}),    # stop takes anything and ignores it
    ("dance", ["wildly"], ["wildly"], {"style": 1}, {}),  # an unknown verb goes on bare: the robot names the verbs
]


@pytest.fixture
def surfaces(net):
    """A simulated Pepper, a gateway in front of it and an OSC client; ``cli(verb, words)``
    runs ``sonibus send`` in-process and gives (status, stdout, stderr)."""
    net.sim("pepper", rate_hz=20)
    gate = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{free_port(socket.SOCK_DGRAM)}"), name="gate"))
    client = Client(gate.udp_address)

    def cli(verb: str, words: list[str]) -> tuple[int, str, str]:
        env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
        status = main(["send", "pepper", verb, *words, "--timeout", "10", *net.cli_args()], env)
        return status, env.stdout.getvalue(), env.stderr.getvalue()

    yield cli, client, gate
    client.sock.close()


def error_line(stderr: str) -> str:
    """The one error line (the gateway and the robot of this process may log beside it)."""
    lines = [line for line in stderr.splitlines() if line.startswith("sonibus: error: ")]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0].removeprefix("sonibus: error: ")


def test_the_same_mistake_is_the_same_error_from_cli_osc_and_json(surfaces):
    cli, client, gate = surfaces
    for verb, words, osc_args, json_value, expected in SHAPING:
        errors = {}
        if words is not None:
            status, out, err = cli(verb, words)
            assert (status, out) == (Exit.USAGE, ""), err
            errors["cli"] = error_line(err)
        if osc_args is not None:
            address, (ok, code, message) = client.ask(f"/pepper/cmd/{verb}", *osc_args)
            assert (address, ok, code) == (f"/pepper/reply/{verb}", 0, "bad_request"), message
            errors["osc"] = message
        with pytest.raises(CommandError) as caught:
            from_json(verb, json_value)
        assert caught.value.code == "bad_request"
        errors["json"] = caught.value.message
        assert set(errors.values()) == {expected}, (verb, errors)
    assert gate.stats["bad_args"] == sum(1 for case in SHAPING if case[2] is not None)
    assert gate.stats["commands"] == 0, "a refused command reached the robot"


def test_what_the_robot_refuses_reads_the_same_from_every_surface(surfaces):
    cli, client, _ = surfaces
    model = load_model("pepper")
    for verb, words, osc_args, json_value, code, fragment in ROBOT:
        status, out, err = cli(verb, words)
        assert (status, out) == (Exit.USAGE if code == "unknown_verb" else Exit.REFUSED, ""), err
        address, (ok, osc_code, message) = client.ask(f"/pepper/cmd/{verb}", *osc_args)
        assert (address, ok, osc_code) == (f"/pepper/reply/{verb}", 0, code), message
        with pytest.raises(CommandError) as caught:
            validate(verb, from_json(verb, json_value), model)
        assert caught.value.code == code
        assert error_line(err) == message == caught.value.message
        assert fragment in message


@pytest.mark.parametrize(("verb", "words", "osc_args", "json_value", "request_"), GOOD,
                         ids=[f"{case[0]}-{i}" for i, case in enumerate(GOOD)])
def test_good_commands_shape_to_one_request(verb, words, osc_args, json_value, request_):
    shaped = [from_words(verb, words), from_osc(verb, osc_args), from_json(verb, json_value)]
    assert shaped == [request_] * 3
    assert all(list(s) == list(request_) for s in shaped), "the schema's order"
    numbers = [v for s in shaped for value in s.values() for v in (value if isinstance(value, list) else [value])
               if not isinstance(v, str | bool)]
    assert all(isinstance(v, float) for v in numbers), "a number is a float from every surface"


def test_a_good_command_reaches_the_robot_alike_from_cli_and_osc(net, surfaces):
    cli, client, _ = surfaces
    subscriber, events = net.bus("watch").subscribe("pepper/events/command")
    status, out, err = cli("say", ["good", "morning", "volume=1", "speed=120"])
    assert status == Exit.OK and "duration" in json.loads(out), err
    address, (ok, _) = client.ask("/pepper/cmd/say", "good", "morning", 1, 120)
    assert (address, ok) == ("/pepper/reply/say", 1)
    seen: list[dict] = []

    def two_events() -> bool:
        while (item := events.get(timeout=0)) is not None:
            seen.append(codec.decode(item[1]))
        return len(seen) >= 2

    wait_for(two_events, what="two command events")
    assert [e["args"] for e in seen] == [GOOD[0][4]] * 2
    subscriber.undeclare()


def test_json_types_are_strict():
    for verb, value, fragment in [
        ("say", {"text": "hi", "volume": True}, "argument 2 (volume) must be a number, got boolean true"),
        ("say", {"text": "hi", "volume": "0.5"}, "argument 2 (volume) must be a number, got string '0.5'"),
        ("joints/set", {"names": "HeadYaw", "angles": [0.3]}, "argument 1 (names) must be a list of strings"),
        ("awareness", {"enabled": 0.5}, "must be T, F, 0 or 1, got float 0.5"),
        ("say", ["hi"], "say: arguments must be a map, got array ['hi']"),
        ("say", {"text": "hi", "speed": 10**400}, "argument 3 (speed) must be a number, got int"),
    ]:
        with pytest.raises(CommandError) as caught:
            from_json(verb, value)
        assert caught.value.code == "bad_request" and fragment in caught.value.message, caught.value.message
