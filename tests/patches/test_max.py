"""The Max patches (patches/max/sonibus.maxpat, patches/pepperosc/pepperosc.maxpat),
read as Max reads them. No Max here: the patcher JSON is checked whole, every OSC
address a [route] after [udpreceive] waits for is one the OSC sink sends (rendered by
the sink's own profile for the installation the patch's comments give), and every
message that reaches [udpsend] is one the gateway takes and the robot accepts."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import routes
from sonibus.adapters.osc.config import OscSinkConfig, parse_target
from sonibus.adapters.osc.gateway import OscGatewayConfig
from sonibus.adapters.osc.profiles import PROFILES
from sonibus.adapters.sim import SimConfig
from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import commands, config, load_model
from sonibus.bus.keys import Key
from sonibus.bus.options import from_mapping

ROOT = Path(__file__).resolve().parents[2]
PATCHES = {"sonibus": ROOT / "patches" / "max" / "sonibus.maxpat",
           "pepperosc": ROOT / "patches" / "pepperosc" / "pepperosc.maxpat"}
MODEL = load_model("pepper")
EVENT_KINDS = re.findall(r"^\| `/pepper/events/(\w+)`", (ROOT / "docs" / "osc.md").read_text(), re.M)


class Patch:
    """A patcher's boxes by id and its patch cords."""

    def __init__(self, path: Path) -> None:
        self.patcher = json.loads(path.read_text(encoding="utf-8"))["patcher"]
        self.boxes = {b["box"]["id"]: b["box"] for b in self.patcher["boxes"]}
        self.cords = [(c["patchline"]["source"], c["patchline"]["destination"]) for c in self.patcher["lines"]]

    def objects(self, name: str) -> list[dict[str, Any]]:
        return [b for b in self.boxes.values() if b["maxclass"] == "newobj" and b["text"].split()[0] == name]

    def out(self, ident: str) -> Iterator[tuple[int, dict[str, Any]]]:
        """(outlet, box) of every cord leaving ``ident``."""
        for (source, outlet), (destination, _) in self.cords:
            if source == ident:
                yield outlet, self.boxes[destination]

    def into(self, ident: str) -> list[dict[str, Any]]:
        return [self.boxes[source] for (source, _), (destination, _) in self.cords if destination == ident]

    def feeding(self, ident: str) -> list[dict[str, Any]]:
        """Every box whose messages reach ``ident``, however far up."""
        seen: dict[str, dict[str, Any]] = {}
        todo = self.into(ident)
        while todo:
            box = todo.pop()
            if box["id"] not in seen:
                seen[box["id"]] = box
                todo += self.into(box["id"])
        return list(seen.values())

    def installation(self) -> config.Installation:
        """The installation the comments give: their ``[nodes.NAME]`` snippets, as one file."""
        snippets = [c["text"][c["text"].index("[nodes."):].split("\n\n")[0]
                    for c in self.boxes.values() if c["maxclass"] == "comment" and "[nodes." in c["text"]]
        assert snippets, "no comment says which node feeds the patch"
        return config.parse("\n\n".join(snippets), "the patch's comments")


def load(name: str) -> Patch:
    return Patch(PATCHES[name])


def sink_messages(sink: OscSinkConfig) -> set[tuple[str, ...]]:
    """What the sink sends to its first target, rendered by its own profile: each message
    as its address and the strings that lead its arguments."""
    profile = PROFILES[sink.resolved_targets()[0].profile](sink.resolved_targets()[0])
    samples = [(Key.parse(f"pepper/joints/{joint}"), [0.0]) for joint in MODEL.joint_names]
    datagrams, _ = profile.frame("pepper", 0.0, 0, samples, 0.01)
    for kind in EVENT_KINDS:
        for state in ("started", "stopped"):
            datagrams.append(profile.event("pepper", kind, {"name": "n", "text": "t", "verb": "say", "ok": True,
                                                            "state": state}))
    out = set()
    for datagram in filter(None, datagrams):
        message = OscMessage(datagram)
        leading = message.params[:next((i for i, a in enumerate(message.params) if not isinstance(a, str)),
                                       len(message.params))]
        out.add((message.address, *leading))
    return out


def routed(patch: Patch, box: dict[str, Any], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every address path the [route]s after ``box`` select: a route's outlet ``i`` adds
    its argument ``i``; its last outlet (no match) passes the message on unchanged."""
    for outlet, after in patch.out(box["id"]):
        words = box["text"].split()
        path = (*prefix, words[1 + outlet]) if words[0] == "route" and outlet < len(words) - 1 else prefix
        if after["maxclass"] == "newobj" and after["text"].split()[0] == "route":
            yield from ((*path, word) for word in after["text"].split()[1:])
            yield from routed(patch, after, path)


def sent(patch: Patch, udpsend: dict[str, Any]) -> Iterator[tuple[dict[str, Any], str, list[Any]]]:
    """(box, address, arguments) of every message reaching ``udpsend``: message boxes as
    written, and [prepend ADDRESS] fed by a [scale] at its low, middle and high output."""
    def value(word: str) -> Any:
        try:
            return float(word) if "." in word else int(word)
        except ValueError:
            return word

    for box in patch.feeding(udpsend["id"]):
        if box["maxclass"] == "message":
            address, *args = shlex.split(box["text"])
            yield box, address, [value(a) for a in args]
        elif box["maxclass"] == "newobj" and box["text"].startswith("prepend "):
            (scale,) = patch.into(box["id"])
            low, high = map(float, scale["text"].split()[3:5])
            for angle in (low, (low + high) / 2, high):
                yield box, box["text"].split()[1], [angle]


@pytest.mark.parametrize("name", PATCHES)
def test_the_patch_is_a_max_patcher_whose_cords_join_existing_boxes(name):
    patch = load(name)
    assert patch.patcher["fileversion"] == 1 and {"major", "minor", "revision"} <= set(patch.patcher["appversion"])
    assert len(patch.patcher["rect"]) == 4 and patch.patcher["boxes"] and patch.patcher["lines"]
    assert len(patch.boxes) == len(patch.patcher["boxes"]), "two boxes share an id"
    for box in patch.boxes.values():
        assert {"id", "maxclass", "numinlets", "numoutlets", "patching_rect"} <= set(box), box
        assert len(box.get("outlettype", [])) == box["numoutlets"], box
    for (source, outlet), (destination, inlet) in patch.cords:
        assert source in patch.boxes and destination in patch.boxes, (source, destination)
        assert 0 <= outlet < patch.boxes[source]["numoutlets"], (source, outlet)
        assert 0 <= inlet < patch.boxes[destination]["numinlets"], (destination, inlet)


@pytest.mark.parametrize("name", PATCHES)
def test_every_address_the_patch_routes_is_one_the_sink_sends_it(name):
    patch = load(name)
    nodes = [s for s in patch.installation().nodes.values() if s.adapter == "osc"]
    assert len(nodes) == 1
    sink = from_mapping(OscSinkConfig, nodes[0].options, nodes[0].where)
    messages = sink_messages(sink)
    (udp,) = patch.objects("udpreceive")
    assert int(udp["text"].split()[1]) == parse_target(sink.resolved_targets()[0].to)[1]
    paths = set(routed(patch, udp))
    for path in paths:
        assert any(m[:len(path)] == path for m in messages), f"{name} routes {path}, which the sink never sends"
    for message in messages:  # every address the sink sends is routed as far as it goes
        depth = next((i for i, word in enumerate(message) if not word.startswith("/")), len(message))
        assert message[:depth] in paths, f"{name} does not route {message[:depth]}"


def test_every_command_the_patch_sends_is_taken_by_the_gateway_and_the_robot():
    patch = load("sonibus")
    (gateway,) = [s for s in patch.installation().nodes.values() if s.adapter == "osc-gateway"]
    listen = from_mapping(OscGatewayConfig, gateway.options, gateway.where).listen
    (udpsend,) = patch.objects("udpsend")
    assert udpsend["text"].split()[1:] == [str(p) for p in parse_target(listen)]
    addresses = set()
    for box, address, args in sent(patch, udpsend):
        target = routes.match(address)
        assert target is not None and target.route in routes.ROUTES, f"{box['id']}: {address} is not a command"
        request = target.request(args)
        commands.validate(target.route.verb, request, MODEL, LIBRARY)  # what the robot's owner checks
        addresses.add(address)
    assert addresses >= {"/pepper/cmd/say", "/pepper/cmd/behavior/run", "/pepper/cmd/stop",
                         "/pepper/cmd/joints/set/HeadYaw", "/pepper/cmd/posture"}
    assert not load("pepperosc").objects("udpsend")


def test_each_slider_spans_its_joints_limits():
    patch = load("sonibus")
    joints = []
    for prepend in (b for b in patch.objects("prepend")):
        target = routes.match(prepend["text"].split()[1])
        assert target is not None and target.route is routes.PER_JOINT
        (scale,) = patch.into(prepend["id"])
        (slider,) = patch.into(scale["id"])
        spec = MODEL.joint(target.joint)
        assert slider["maxclass"] == "slider" and slider["floatoutput"] == 1 and slider["size"] == 1.0
        assert [float(w) for w in scale["text"].split()[1:]] == [0.0, 1.0, spec.min, spec.max]
        joints.append(target.joint)
    assert {"HeadYaw", "HeadPitch"} <= set(joints)


def test_the_committed_patches_are_what_make_maxpat_writes(tmp_path):
    subprocess.run([sys.executable, str(ROOT / "patches" / "max" / "make_maxpat.py"), "--output", str(tmp_path)],
                   check=True, capture_output=True, timeout=60)
    for path in PATCHES.values():
        fresh = tmp_path / path.parent.name / path.name
        assert json.loads(fresh.read_text()) == json.loads(path.read_text()), \
            f"{path.name} is out of date: run patches/max/make_maxpat.py and commit it"


def test_the_readme_installations_load():
    blocks = re.findall(r"```toml\n(.*?)```", (ROOT / "patches" / "max" / "README.md").read_text(), re.S)
    configs = {"sim": SimConfig, "osc": OscSinkConfig, "osc-gateway": OscGatewayConfig}
    nodes = [n for block in blocks for n in config.parse(block, "patches/max/README.md").nodes.values()]
    checked = {n.adapter: from_mapping(configs[n.adapter], n.options, n.where) for n in nodes if n.name != "pepperosc"}
    assert parse_target(checked["osc"].resolved_targets()[0].to)[1] == 9000
    assert parse_target(checked["osc-gateway"].listen)[1] == 9001
    (pepperosc,) = (n for n in nodes if n.name == "pepperosc")
    assert from_mapping(OscSinkConfig, pepperosc.options, pepperosc.where).resolved_targets()[0].profile == "pepperosc"
