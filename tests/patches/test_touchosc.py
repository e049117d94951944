"""The TouchOSC surface (patches/touchosc/sonibus.tosc), read as TouchOSC reads it
(zlib → lexml), and every message its controls would send played over UDP to a
running OSC gateway with a simulated Pepper behind it."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import xml.etree.ElementTree as ET
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from ipaddress import ip_address
from pathlib import Path
from typing import Any

import pytest

from sonibus.adapters.osc import routes
from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import config, robot_info
from sonibus.bus.options import from_mapping

from ..conftest import free_port, wait_for
from ..osc.test_gateway import Client, Watch

SURFACE = Path(__file__).resolve().parents[2] / "patches" / "touchosc"
TOSC = SURFACE / "sonibus.tosc"
FADERS = ("HeadYaw", "HeadPitch", "LShoulderPitch", "RShoulderPitch", "LElbowRoll")  # the brief's, at least
CONVERT = {"STRING": str, "FLOAT": float, "INTEGER": lambda v: int(float(v)), "BOOLEAN": lambda v: float(v) != 0}


@dataclass(frozen=True)
class Sent:
    """One message a control sends, at one value of its ``x``."""

    control: str
    kind: str
    address: str
    args: tuple[Any, ...]
    x: float


def load(path: Path = TOSC) -> ET.Element:
    root = ET.fromstring(zlib.decompress(path.read_bytes()))
    assert root.tag == "lexml" and [n.get("type") for n in root.findall("node")] == ["GROUP"]
    return root


def prop(node: ET.Element, key: str) -> str:
    for item in node.findall("properties/property"):
        if item.findtext("key") == key:
            return item.findtext("value") or ""
    raise AssertionError(f"{node.get('type')} {node.get('ID')} has no property '{key}'")


def xs(node: ET.Element, osc: ET.Element) -> list[float]:
    """The values of ``x`` at which a control sends: a fader at its min, middle and max;
    a button (x 1 pressed, 0 released) when its trigger fires."""
    out: list[float] = []
    for trigger in osc.findall("triggers/trigger"):
        var, condition = trigger.findtext("var"), trigger.findtext("condition")
        assert var == "x", f"{prop(node, 'name')}: a trigger on '{var}' (this reader knows x only)"
        if node.get("type") == "FADER":
            out += [0.0, 0.5, 1.0]
        else:
            out += {"RISE": [1.0], "FALL": [0.0], "ANY": [1.0, 0.0]}[condition or ""]
    return out


def render(node: ET.Element, partial: ET.Element, x: float) -> Any:
    kind, value = partial.findtext("type"), partial.findtext("value") or ""
    if kind == "CONSTANT":
        raw: Any = value
    elif kind == "PROPERTY":
        raw = prop(node, value)
    elif kind == "VALUE" and value == "x":
        low, high = float(partial.findtext("scaleMin") or 0), float(partial.findtext("scaleMax") or 1)
        raw = low + x * (high - low)
    else:
        raise AssertionError(f"{prop(node, 'name')}: a {kind} partial of '{value}' (this reader cannot render it)")
    return CONVERT[partial.findtext("conversion") or ""](raw)


def sent(root: ET.Element) -> Iterator[Sent]:
    """Every message every control sends, in the order of the layout."""
    for node in root.iter("node"):
        for osc in node.findall("messages/osc"):
            if osc.findtext("enabled") != "1" or osc.findtext("send") != "1":
                continue
            for x in xs(node, osc):
                address = "".join(str(render(node, p, x)) for p in osc.findall("path/partial"))
                args = tuple(render(node, p, x) for p in osc.findall("arguments/partial"))
                yield Sent(prop(node, "name"), node.get("type") or "", address, args, x)


def fader_ranges(root: ET.Element) -> dict[str, tuple[float, float]]:
    """Joint → the (min, max) its fader sends."""
    ranges = {}
    for node in root.iter("node"):
        if node.get("type") == "FADER":
            for osc in node.findall("messages/osc"):
                target = routes.match(osc.findtext("path/partial/value") or "")
                assert target is not None and target.route is routes.PER_JOINT, prop(node, "name")
                (value,) = osc.findall("arguments/partial")
                ranges[target.joint] = (float(value.findtext("scaleMin") or ""),
                                        float(value.findtext("scaleMax") or ""))
    return ranges


@pytest.fixture
def client(net):
    """A UDP client of a running OSC gateway, a simulated Pepper behind it."""
    net.sim("pepper", rate_hz=50)
    gateway = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{free_port(socket.SOCK_DGRAM)}"), name="gate"))
    client = Client(gateway.udp_address)
    yield client
    client.sock.close()


def test_every_message_of_the_surface_is_accepted_by_the_gateway(net, client):
    messages = list(sent(load()))
    info = robot_info(net.bus("info"), "pepper")
    assert {m.args[0] for m in messages if m.address == "/pepper/cmd/behavior/run"} == set(info["behaviors"])
    assert {m.address for m in messages} >= {"/pepper/cmd/say", "/pepper/cmd/stop",
                                              *(f"/pepper/cmd/joints/set/{j}" for j in FADERS)}
    for message in messages:
        target = routes.match(message.address)
        assert target is not None and target.route in routes.ROUTES, message
        address, params = client.ask(message.address, *message.args)
        assert (address, params[:1]) == (f"/pepper/reply/{target.sent}", [1]), (message, params)
    assert len(messages) >= len(info["behaviors"]) + 3 * len(FADERS) + 2


def test_the_stop_button_stops_the_robot(net, client):
    messages = list(sent(load()))
    (stop,) = (m for m in messages if m.address == "/pepper/cmd/stop")
    wave = next(m for m in messages if m.address == "/pepper/cmd/behavior/run")
    behaviors, speech, postures = (Watch(net, f"pepper/events/{kind}") for kind in ("behavior", "speech", "posture"))
    arm = Watch(net, "pepper/joints/RShoulderPitch")

    def seen(watch: Watch, **fields: str) -> bool:
        return any(fields.items() <= event.items() for event in watch.all())

    assert client.ask(wave.address, *wave.args)[1][0] == 1
    wait_for(lambda: seen(behaviors, name=wave.args[0], state="started"), what="the behavior started")
    text = "a long speech " * 35  # 105 words at half speed, ~80 s: it ends that soon only if stopped
    assert client.ask("/pepper/cmd/say", text.strip(), 1, 50)[1][0] == 1
    wait_for(lambda: seen(speech, state="started"), what="the speech started")
    address, (ok, result) = client.ask(stop.address, *stop.args)
    assert (address, ok) == ("/pepper/reply/stop", 1) and json.loads(result)["held"] is True
    wait_for(lambda: seen(behaviors, name=wave.args[0], state="stopped"), what="the behavior stopped")
    wait_for(lambda: seen(speech, state="done"), what="the speech cut short")
    arm.steady()

    assert client.ask("/pepper/cmd/posture", "Crouch", 0.02)[1][0] == 1  # ~50 s to crouch that slowly
    wait_for(lambda: seen(postures, name="Crouch", state="started"), what="the posture started")
    assert client.ask(stop.address, *stop.args)[1][0] == 1
    wait_for(lambda: seen(postures, name="Crouch", state="interrupted"), what="the posture interrupted")
    arm.steady()


def test_faders_span_the_limits_the_robot_serves(net):
    net.sim("pepper")
    info = robot_info(net.bus("info"), "pepper")
    limits = {j["name"]: (j["min"], j["max"]) for j in info["joints"]}
    ranges = fader_ranges(load())
    assert set(ranges) >= set(FADERS)
    assert ranges == {joint: limits[joint] for joint in ranges}


def test_the_committed_surface_is_what_make_tosc_writes(tmp_path):
    out = tmp_path / "fresh.tosc"
    subprocess.run([sys.executable, str(SURFACE / "make_tosc.py"), "--output", str(out)], check=True,
                   capture_output=True, timeout=60)
    assert zlib.decompress(out.read_bytes()) == zlib.decompress(TOSC.read_bytes()), \
        "sonibus.tosc is out of date: run patches/touchosc/make_tosc.py and commit it"


def test_the_readme_gateway_takes_a_tablet_on_wifi():
    (block,) = re.findall(r"```toml\n(.*?)```", (SURFACE / "README.md").read_text(), re.S)
    (node,) = config.parse(block, "patches/touchosc/README.md").nodes.values()
    gateway = from_mapping(OscGatewayConfig, node.options, node.where)
    assert node.adapter == "osc-gateway" and gateway.listen == "0.0.0.0:9001"
    assert any(ip_address("192.168.1.37") in network for network in gateway.networks())
    assert not any(ip_address("10.0.0.5") in network for network in gateway.networks())
