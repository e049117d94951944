"""The OSC command gateway: liblo and python-osc clients, a simulated Pepper, real UDP and TCP."""

from __future__ import annotations

import json
import logging
import select
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from pythonosc import slip
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus import schemas
from sonibus.adapters.osc import routes
from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.adapters.show import Show, ShowConfig
from sonibus.bus import ConfigError, codec, robot_info
from sonibus.bus.commands import ok_reply
from sonibus.bus.options import from_mapping

from ..conftest import free_port, require_tool, wait_for
from ..wakes import left_after_stop, named, wakes

DOCS = Path(__file__).resolve().parents[2] / "docs"


def build(address: str, *args: Any) -> bytes:
    builder = OscMessageBuilder(address)
    for arg in args:
        builder.add_arg(arg)
    return builder.build().dgram


def bundle(*elements: bytes) -> bytes:
    """An OSC bundle, time tag 'immediately', of raw elements (which may be broken)."""
    return b"#bundle\0" + (1).to_bytes(8, "big") + b"".join(len(e).to_bytes(4, "big") + e for e in elements)


class Client:
    """A UDP OSC client on a port of its own: sends commands and reads the replies."""

    def __init__(self, target: tuple[Any, ...], host: str = "127.0.0.1") -> None:
        self.target = target[:2]
        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.sock.settimeout(5.0)

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.target)

    def ask(self, address: str, *args: Any) -> tuple[str, list[Any]]:
        self.send(build(address, *args))
        return self.reply()

    def reply(self) -> tuple[str, list[Any]]:
        message = OscMessage(self.sock.recv(65536))
        return message.address, message.params

    def nothing_waiting(self) -> bool:
        return not select.select([self.sock], [], [], 0)[0]


class Watch:
    """Decoded samples of a key expression, gathered as they arrive."""

    def __init__(self, net: Any, keyexpr: str) -> None:
        bus = net.bus("watch")
        self.subscriber, self.queue = bus.subscribe(keyexpr)
        self.seen: list[dict[str, Any]] = []
        # Ready once a frame arrives on a subscription declared after it on the same link: an
        # event put right after this returns is not missed (the robot streams frames all along).
        frames, arrived = bus.subscribe("pepper/frame")
        try:
            wait_for(lambda: arrived.get(timeout=0.05), what="pepper's frames (the watch in place)")
        finally:
            frames.undeclare()

    def all(self) -> list[dict[str, Any]]:
        while (item := self.queue.get(timeout=0)) is not None:
            self.seen.append(codec.decode(item[1]))
        return self.seen

    def steady(self, frames: int = 10) -> float:
        """Wait for ``frames`` more samples and return their one value (the joint did not move)."""
        start = len(self.all())
        wait_for(lambda: len(self.all()) >= start + frames, what=f"{frames} joint samples")
        values = {round(s["v"], 6) for s in self.seen[start:]}
        assert len(values) == 1, f"the joint moved: {sorted(values)[:5]}"
        return values.pop()


@pytest.fixture
def gate(net):
    net.sim("pepper", rate_hz=50)
    port = free_port(socket.SOCK_DGRAM)
    return net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{port}"), name="gate"))


@pytest.fixture
def client(gate):
    client = Client(gate.udp_address)
    yield client
    client.sock.close()


def test_oscsend_makes_the_robot_speak_and_a_python_client_gets_replies(net, gate, client):
    oscsend = require_tool("oscsend", "liblo-tools")
    speech = Watch(net, "pepper/events/speech")
    # (watched before any command: a subscription declared after one can miss its event)
    commands = Watch(net, "pepper/events/command")
    subprocess.run([oscsend, "localhost", str(gate.udp_address[1]), "/pepper/cmd/say", "s", "hello"],
                   check=True, timeout=10)
    wait_for(lambda: {"text": "hello", "state": "started"}.items() <= (speech.all() or [{}])[-1].items(),
             what="the robot speaking 'hello'")
    address, (ok, result) = client.ask("/pepper/cmd/say", "good", "morning", 1, 120)  # words as Pd sends them
    assert (address, ok) == ("/pepper/reply/say", 1)
    assert json.loads(result)["queued"] in (0, 1)
    event = wait_for(lambda: [e for e in commands.all() if e["args"].get("text") == "good morning"],
                     what="the command event")[-1]
    assert event["args"] == {"text": "good morning", "volume": 1.0, "speed": 120.0}


def test_behavior_posture_stop_and_list_round_trip(net, client):
    behaviors = Watch(net, "pepper/events/behavior")
    hey = "animations/Stand/Gestures/Hey_1"
    assert client.ask("/pepper/cmd/behavior/run", hey)[1][0] == 1
    wait_for(lambda: any(e["name"] == hey and e["state"] == "started" for e in behaviors.all()), what="started")
    address, (ok, result) = client.ask("/pepper/cmd/behavior/list")
    assert (address, ok) == ("/pepper/reply/behavior/list", 1) and hey in json.loads(result)["behaviors"]
    address, (ok, result) = client.ask("/pepper/cmd/stop", 1.0)  # a button's 1.0 is ignored
    assert (address, ok) == ("/pepper/reply/stop", 1)
    assert json.loads(result) == {"held": True, "cut": [hey], "silenced": 0}  # (what it did: issue 37; it was {})
    wait_for(lambda: any(e["name"] == hey and e["state"] == "stopped" for e in behaviors.all()), what="stopped")
    assert client.ask("/pepper/cmd/posture", "Crouch", 1) == ("/pepper/reply/posture", [1, '{"name":"Crouch"}'])
    assert client.ask("/pepper/cmd/behavior/stop") == ("/pepper/reply/behavior/stop", [1, '{"was_running":false}'])
    assert client.ask("/pepper/cmd/awareness", 1)[1][0] == 1
    assert client.ask("/pepper/cmd/stiffness", "Head", "LArm", 1)[1][0] == 1


def test_joints_set_moves_the_joint_and_an_invalid_angle_moves_nothing(net, client):
    head = Watch(net, "pepper/joints/HeadYaw")
    start = head.steady(3)
    assert client.ask("/pepper/cmd/joints/set", "HeadYaw", 0.5, "HeadPitch", 0, 1) == \
        ("/pepper/reply/joints/set", [1, '{"targets":{"HeadYaw":0.5,"HeadPitch":0.0},"speed":1.0}'])
    wait_for(lambda: abs(head.all()[-1]["v"] - 0.5) < 1e-6, what="HeadYaw at 0.5")
    assert start != pytest.approx(0.5)
    address, (ok, code, message) = client.ask("/pepper/cmd/joints/set", "HeadYaw", 3.0)
    assert (address, ok, code) == ("/pepper/reply/joints/set", 0, "out_of_range")
    assert "HeadYaw = 3.0" in message and "\n" not in message
    assert head.steady() == pytest.approx(0.5, abs=1e-3)


def test_one_joint_per_address_for_a_fader(net, client):
    """``/pepper/cmd/joints/set/<Joint> angle [speed]``: one float moves one joint; the
    reply goes to the address as sent; a wrong joint or angle moves nothing."""
    head = Watch(net, "pepper/joints/HeadYaw")
    address, (ok, result) = client.ask("/pepper/cmd/joints/set/HeadYaw", -0.4, 1.0)
    assert (address, ok) == ("/pepper/reply/joints/set/HeadYaw", 1)
    assert json.loads(result)["targets"]["HeadYaw"] == pytest.approx(-0.4)  # (OSC's float32)
    wait_for(lambda: head.all() and abs(head.seen[-1]["v"] + 0.4) < 1e-6, what="HeadYaw at -0.4")
    for args, code in (([3.0], "out_of_range"), (["far"], "bad_request"), ([], "bad_request")):
        address, (ok, got, message) = client.ask("/pepper/cmd/joints/set/HeadYaw", *args)
        assert (address, ok, got) == ("/pepper/reply/joints/set/HeadYaw", 0, code), message
    address, (ok, code, message) = client.ask("/pepper/cmd/joints/set/Tail", 0.1)
    assert (ok, code) == (0, "unknown_joint") and "Tail" in message
    assert head.steady() == pytest.approx(-0.4, abs=1e-3)


def test_every_route_accepts_the_arguments_it_declares(net, client):
    """What OSCQuery tells a client to send (each route's type tags, values in its ranges and
    choices) the gateway takes: ``N`` (no argument) included, which behavior/list and
    behavior/stop refused as 'nil has no place'. The scenario route asks pepper's show."""
    net.start(Show(ShowConfig(robot="pepper", scenarios={"hello": {"steps": [{"say": "Hello"}]}}), name="show"))
    info = robot_info(net.bus("info"), "pepper")
    limits = {j["name"]: (j["min"], j["max"]) for j in info["joints"]}
    choices = {"behaviors": info["behaviors"][0], "postures": "Stand", "joints": "HeadYaw", "stiffness": "Head"}
    for route in routes.ROUTES:
        args: list[Any] = []
        for slot in route.slots:
            if slot.tag == "s":
                args.append(choices.get(slot.choices, "hello"))
            elif slot.tag == "T":
                args.append(True)
            else:  # f: the middle of the joint's limits, or of the schema's bounds
                low, high = limits["HeadYaw"] if slot.choices in ("limits", "") and slot.name == "angles" \
                    else route.bounds(slot)
                args.append(((low or 0.0) + (high if high is not None else 1.0)) / 2)
        if route.types == "N":
            args = [None]  # a client that sends what TYPE "N" says: one nil
        address = route.address("pepper", joint="HeadYaw")
        reply, values = client.ask(address, *args)
        assert (reply, values[0]) == (address.replace(f"/{route.section}/", "/reply/"), 1), (address, args, values)


ERRORS = [
    ("/nao/cmd/stop", [], "robot_not_found", "robot 'nao' not found"),
    ("/pepper/cmd/say", [3], "bad_request", "argument 1 (text) must be a string, got int 3"),
    ("/pepper/cmd/say", ["hi", 0.5, "loud"], "bad_request", "argument 3 (speed) must be a number"),
    ("/pepper/cmd/joints/set", [0.3, "HeadYaw"], "bad_request", "argument 1 is float 0.3"),
    ("/pepper/cmd/joints/set", ["HeadYaw", "HeadPitch"], "bad_request", "must be followed by its angle"),
    ("/pepper/cmd/awareness", [0.5], "bad_request", "must be T, F, 0 or 1"),
    ("/pepper/cmd/behavior/run", [b"\x01\x02"], "bad_request", "got a blob of 2 bytes"),
    ("/pepper/cmd/behavior/list", ["extra"], "bad_request", "takes no arguments"),
    ("/pepper/cmd/say", list(range(65)), "bad_request", "65 arguments, at most 64"),
    ("/pepper/cmd/posture", ["Sit"], "unknown_posture", "unknown posture 'Sit'"),  # the robot's own check
    ("/pepper/cmd/dance", [], "unknown_verb", "unknown command 'dance'"),
]


def test_errors_are_answered_with_code_and_one_line(gate, client):
    for address, args, code, fragment in ERRORS:
        reply_address, (ok, got_code, message) = client.ask(address, *args)
        assert (reply_address, ok, got_code) == (address.replace("/cmd/", "/reply/"), 0, code), message
        assert fragment in message and "\n" not in message
    assert gate.stats["bad_args"] == 8 and gate.stats["replies_error"] == len(ERRORS)


def test_bundles_are_unpacked_and_a_bad_element_refuses_the_whole_bundle(gate, client):
    client.send(bundle(build("/pepper/cmd/say", "bundled"), bundle(build("/pepper/cmd/behavior/list"))))
    replies = sorted([client.reply(), client.reply()])
    assert [(a, p[0]) for a, p in replies] == [("/pepper/reply/behavior/list", 1), ("/pepper/reply/say", 1)]
    bad_tag = b"/pepper/cmd/say\0,c\0\0\0\0\0A"
    client.send(bundle(build("/pepper/cmd/say", "bundled"), bad_tag,
                       bundle(build("/pepper/cmd/behavior/list"), b"garbage!")))
    replies = sorted([client.reply(), client.reply(), client.reply()])  # one per readable command address
    assert [(a, p[:2]) for a, p in replies] == [("/pepper/reply/behavior/list", [0, "bad_request"])] + \
        [("/pepper/reply/say", [0, "bad_request"])] * 2
    assert all("element 2: type tag 'c' (argument 1) is not supported" in p[2] for _, p in replies)
    wait_for(lambda: gate.stats["malformed"] == 1, what="the bad bundle counted")
    client.send(b"/not/a/command\0\0,\0\0\0")
    wait_for(lambda: gate.stats["unknown_address"] == 1, what="unknown address counted")
    assert gate.stats["commands"] == 2 and client.nothing_waiting()


@pytest.fixture
def slow_robot(net):
    """A robot owner that answers only when the test says so."""
    held: list[Any] = []
    net.bus("slowbot").serve("slowbot/cmd/**", held.append)
    yield held
    held.clear()


def answer(held: list[Any], result: dict[str, Any]) -> None:
    """The slow robot answers its oldest command."""
    wait_for(lambda: held, what="the command at the robot")
    query = held.pop(0)
    query.reply(query.key_expr, codec.encode(ok_reply("behavior/list", result)), encoding=codec.ENCODING)
    query.drop()


def test_a_reply_reaches_oscdump_listening_on_the_senders_port(net, spawn, slow_robot):
    oscdump = require_tool("oscdump", "liblo-tools")
    gate = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0"), name="gate"))
    sender = Client(gate.udp_address)
    port = sender.sock.getsockname()[1]
    sender.send(build("/slowbot/cmd/behavior/list"))
    wait_for(lambda: slow_robot, what="the command at the robot")
    sender.sock.close()  # the reply will go to this port: oscdump takes it over
    dump = spawn(oscdump, "-L", str(port), collect=True)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        wait_for(lambda: probe.sendto(build("/probe"), ("127.0.0.1", port)) and dump.lines, what="oscdump up")
    answer(slow_robot, {"behaviors": ["Wave"]})
    line = wait_for(lambda: next((x for x in dump.lines if "/slowbot/reply/behavior/list" in x), None),
                    what="the reply at oscdump")
    assert line.split()[2:] == ["is", "1", '"{"behaviors":["Wave"]}"']


def test_ipv6_and_replies_off(net, slow_robot):
    gate = net.start(OscGateway(OscGatewayConfig(listen="[::1]:0"), name="gate6"))
    client = Client(gate.udp_address, host="::1")
    client.send(build("/slowbot/cmd/behavior/list"))
    answer(slow_robot, {"behaviors": []})
    assert client.reply() == ("/slowbot/reply/behavior/list", [1, '{"behaviors":[]}'])
    quiet = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0", reply=False), name="quiet"))
    client = Client(quiet.udp_address)
    client.send(build("/slowbot/cmd/behavior/list"))
    answer(slow_robot, {"behaviors": []})
    wait_for(lambda: quiet.stats["replies_ok"] == 1, what="the outcome counted")
    assert client.nothing_waiting()


def test_a_robot_that_does_not_answer_times_out(net, slow_robot):
    gate = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0", timeout=0.5), name="gate"))
    client = Client(gate.udp_address)
    started = time.monotonic()
    address, (ok, code, message) = client.ask("/slowbot/cmd/stop")
    assert (address, ok, code) == ("/slowbot/reply/stop", 0, "timeout")
    assert time.monotonic() - started > 0.45 and "within 0.5 s" in message  # not before its 0.5 s


def test_tcp_slip_and_liblo_size_prefix_are_answered_on_the_same_connection(net):
    net.sim("pepper", rate_hz=50)
    gate = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0", tcp="127.0.0.1:0"), name="gate"))
    with socket.create_connection(gate.tcp_address[:2], timeout=5) as conn:
        conn.sendall(slip.encode(build("/pepper/cmd/say", "over tcp")) + slip.encode(build("/pepper/cmd/stop")))
        data = b""
        while data.count(slip.END) < 4:
            data += conn.recv(65536)
    frames = [OscMessage(slip.decode(f)) for f in data.split(slip.END) if f]
    assert sorted((m.address, m.params[0]) for m in frames) == [("/pepper/reply/say", 1), ("/pepper/reply/stop", 1)]
    speech = Watch(net, "pepper/events/speech")
    oscsend = require_tool("oscsend", "liblo-tools")
    subprocess.run([oscsend, f"osc.tcp://127.0.0.1:{gate.tcp_address[1]}", "/pepper/cmd/say", "s", "liblo"],
                   check=True, timeout=10)
    wait_for(lambda: any(e["text"] == "liblo" for e in speech.all()), what="speech sent by liblo over TCP")


def test_sources_outside_the_allow_list_are_ignored(net, caplog):
    net.sim("pepper", rate_hz=50)
    config = OscGatewayConfig(listen="127.0.0.1:0", tcp="127.0.0.1:0", allow=("10.0.0.0/8",))
    gate = net.start(OscGateway(config, name="gate"))
    head = Watch(net, "pepper/joints/HeadYaw")
    start = head.steady(3)
    client = Client(gate.udp_address)
    with caplog.at_level(logging.WARNING, "sonibus"):
        client.send(build("/pepper/cmd/joints/set", "HeadYaw", 1.0, 1.0))
        wait_for(lambda: gate.stats["refused_source"] == 1, what="the packet refused")
        with socket.create_connection(gate.tcp_address[:2], timeout=5) as conn:
            assert conn.recv(100) == b""  # closed at once
    assert gate.stats["refused_source"] == 2 and gate.stats["commands"] == 0
    assert head.steady() == start and client.nothing_waiting()
    assert sum("not in allow" in r.message for r in caplog.records) == 1  # rate-limited


def test_stop_is_prompt_and_logs_the_counters(net, gate, client, caplog):
    client.ask("/pepper/cmd/behavior/list")
    started = time.monotonic()
    with caplog.at_level(logging.INFO, "sonibus"):
        gate.stop()
    assert time.monotonic() - started < 3.0  # the node's 3 s; its workers ended by themselves:
    assert "did not stop within" not in caplog.text
    assert gate.state == "stopped" and any("commands 1" in r.message for r in caplog.records)
    gate.stop()


@pytest.mark.parametrize(("options", "key"), [
    ({"listen": "9001"}, "listen"), ({"listen": "localhost:70000"}, "listen"), ({"tcp": "nohost"}, "tcp"),
    ({"allow": ("10.0.0.0/33",)}, "allow"), ({"allow": ("pepper",)}, "allow"), ({"allow": ()}, "allow"),
    ({"timeout": 0}, "timeout"), ({"max_args": 0}, "max_args"),
])
def test_bad_options_are_config_errors_naming_the_key(options, key):
    with pytest.raises(ConfigError, match=f"^key '{key}': ") as caught:
        OscGatewayConfig(**options)
    assert "\n" not in str(caught.value)
    with pytest.raises(ConfigError, match=rf"^show.toml \[nodes.gate\]: key '{key}'"):
        from_mapping(OscGatewayConfig, options, "show.toml [nodes.gate]")


def test_a_port_in_use_is_a_clear_error(net):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        gate = OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{taken.getsockname()[1]}"), name="gate")
        with pytest.raises(ConfigError, match=r"node 'gate': key 'listen': .* is already in use"):
            gate.start(net.bus())
    assert gate.state == "stopped"


def test_the_doc_and_the_routes_cover_every_verb():
    text = (DOCS / "osc-gateway.md").read_text(encoding="utf-8")
    assert all(f"/cmd/{verb}" in text for verb in schemas.command_verbs())
    assert {r.verb for r in routes.ROUTES if r.section == "cmd"} == set(schemas.command_verbs())
    assert all(f"/program/{r.verb}" in text for r in routes.ROUTES if r.section == "program")
    for route in routes.ROUTES:  # what OSCQuery declares is what the gateway takes
        schema = schemas.request_schema(route.section, route.verb)
        assert {s.name for s in route.slots} <= set(schema.get("properties", {})), route.path
        given_by_address = {"names"} if route is routes.PER_JOINT else set()
        assert {s.name for s in route.slots} | given_by_address >= set(schema.get("required", ())), route.path


def test_an_idle_gateway_sleeps_until_a_datagram_or_a_reply_and_stops_at_once(net, gate, client):
    """The UDP worker sleeps until a datagram comes (the kernel's drops looked at once after the
    last), the reply worker until a reply is due (before: 0.2 s timeouts, 5 wake-ups a second
    each; issue 35); stopped, both end at once."""
    address, (ok, _) = client.ask("/pepper/cmd/say", "hello")
    assert (address, ok) == ("/pepper/reply/say", 1)
    time.sleep(1.2)  # (past DROPS_EVERY_S: the look after the last datagram done, not counted below)
    counted = wakes(named("gate:"), 2.0)
    # (a count: a thread that waits for the GIL counts a switch too; before: udp 10, reply 10)
    assert counted["gate:udp"] <= 1 and counted["gate:reply"] <= 1, counted
    address, (ok, _) = client.ask("/pepper/cmd/say", "again")  # (asleep, it still answers)
    assert (address, ok) == ("/pepper/reply/say", 1)
    assert not left_after_stop(gate, "gate:")  # (each woken by the stop: not left to its join's 2 s)
