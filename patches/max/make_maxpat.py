"""Write the Max patches: patches/max/sonibus.maxpat (what the OSC sink sends, and
commands through the OSC gateway) and patches/pepperosc/pepperosc.maxpat
(PepperOSC's routing, fed by the sink's pepperosc profile), from the robot's model
(bus/robots.json) and the simulator's behaviors, so that every slider spans its
joint's limits.

    .venv/bin/python patches/max/make_maxpat.py [--robot pepper]

A .maxpat is the JSON Max 8 and 9 save: ``{"patcher": {"fileversion": 1, "appversion",
"rect", "boxes": [{"box": {...}}], "lines": [{"patchline": {"source": [id, outlet],
"destination": [id, inlet]}}]}}``. Edit the patches in Max freely; run this again only
to start over from the robot's model.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import load_model
from sonibus.bus.robot import RobotModel

PATCHES = Path(__file__).resolve().parents[1]
SLIDERS = ("HeadYaw", "HeadPitch", "LShoulderPitch", "RShoulderPitch")
EVENTS = ("behavior", "speech", "posture", "command", "connection", "show", "scenario")  # docs/osc.md, "Events"
ROW = 30.0


def _ports(text: str) -> tuple[int, list[str]]:
    """Inlets and outlet types of a Max object box, as Max 8 reports them."""
    name, *args = text.split()
    n = len(args)
    known: dict[str, tuple[int, list[str]]] = {
        "udpreceive": (1, [""]), "udpsend": (1, []), "route": (2, [""] * (n + 1)), "prepend": (1, [""]),
        "scale": (6, [""]), "line": (3, ["", "bang"]), "line~": (2, ["signal", "bang"]),
        "pack": (max(n, 2), [""]), "unpack": (1, [""] * max(n, 2)), "sel": (1 if n > 1 else 2, ["bang"] * n + [""]),
        "print": (1, []), "*": (2, ["float"]), "cycle~": (2, ["signal"]), "*~": (2, ["signal"]),
    }
    return known[name]


@dataclass
class Patcher:
    """Boxes and patch cords, numbered as Max numbers them (``obj-1``, ...)."""

    width: float
    height: float
    boxes: list[dict[str, Any]] = field(default_factory=list)
    lines: list[dict[str, Any]] = field(default_factory=list)

    def add(self, maxclass: str, rect: tuple[float, float, float, float], inlets: int, outlets: list[str],
            **attributes: Any) -> str:
        ident = f"obj-{len(self.boxes) + 1}"
        box = {"id": ident, "maxclass": maxclass, "numinlets": inlets, "numoutlets": len(outlets),
               "patching_rect": [round(float(v), 1) for v in rect], **attributes}
        if outlets:
            box["outlettype"] = outlets
        self.boxes.append({"box": dict(sorted(box.items()))})
        return ident

    def obj(self, text: str, x: float, y: float, width: float = 0.0, lines: int = 1) -> str:
        inlets, outlets = _ports(text)
        extra = {"linecount": lines} if lines > 1 else {}
        return self.add("newobj", (x, y, width or 12 + 7 * len(text), 8 + 14 * lines), inlets, outlets,
                        text=text, **extra)

    def message(self, text: str, x: float, y: float, **attributes: Any) -> str:
        size = attributes.get("fontsize", 12.0) / 12.0
        return self.add("message", (x, y, 12 + 7 * len(text) * size, 22 * size), 2, [""], text=text, **attributes)

    def comment(self, text: str, x: float, y: float, width: float = 200.0, **attributes: Any) -> str:
        lines = text.count("\n") + 1
        extra = {"linecount": lines} if lines > 1 else {}
        return self.add("comment", (x, y, width, 6 + 14 * lines), 1, [], text=text, **extra, **attributes)

    def flonum(self, x: float, y: float) -> str:
        return self.add("flonum", (x, y, 60, 22), 1, ["", "bang"], format=6, parameter_enable=0)

    def button(self, x: float, y: float) -> str:
        return self.add("button", (x, y, 24, 24), 1, ["bang"], parameter_enable=0)

    def connect(self, source: str, outlet: int, destination: str, inlet: int = 0) -> None:
        self.lines.append({"patchline": {"destination": [destination, inlet], "source": [source, outlet]}})

    def document(self) -> dict[str, Any]:
        return {"patcher": {
            "fileversion": 1,
            "appversion": {"major": 8, "minor": 6, "revision": 5, "architecture": "x64", "modernui": 1},
            "classnamespace": "box", "rect": [60.0, 80.0, self.width, self.height], "bglocked": 0,
            "openinpresentation": 0, "default_fontsize": 12.0, "default_fontface": 0, "default_fontname": "Arial",
            "gridonopen": 1, "gridsize": [15.0, 15.0], "gridsnaponopen": 1, "objectsnaponopen": 1,
            "statusbarvisible": 2, "toolbarvisible": 1, "boxanimatetime": 200, "enablehscroll": 1,
            "enablevscroll": 1, "devicewidth": 0.0, "description": "", "digest": "", "tags": "", "style": "",
            "subpatcher_template": "", "assistshowspatchername": 0,
            "boxes": self.boxes, "lines": self.lines,
        }}


def ladder(patch: Patcher, source: str, outlet: int, x: float, y: float, groups: list[list[str]],
           step: float) -> tuple[dict[str, tuple[str, int, float]], float]:
    """One [route] per group of addresses, each fed by the previous one's last outlet
    (what it did not match), ``step`` wide per outlet and ``ROW * 4`` apart. Returns each
    address's (route, outlet, x of that outlet) and the y below the last route."""
    found: dict[str, tuple[str, int, float]] = {}
    for group in groups:
        text = "route " + " ".join(group)
        width = step * (len(group) + 1)
        route = patch.obj(text, x, y, width, lines=1 if 12 + 7 * len(text) <= width else 2)
        patch.connect(source, outlet, route)
        for i, address in enumerate(group):
            found[address] = (route, i, x + i * (width - 10) / len(group))
        source, outlet = route, len(group)
        y += ROW * 4
    return found, y


def _header(patch: Patcher, text: str, x: float, y: float) -> float:
    patch.comment(text, x, y, 520)
    return y + 20 + 14 * (text.count("\n") + 1)


def _chains(model: RobotModel) -> list[tuple[str, ...]]:
    return [model.chain(c) for c in dict.fromkeys(j.chain for j in model.joints)]


def sonibus_patch(robot: str, model: RobotModel) -> Patcher:
    """Joints and events from the OSC sink on port 9000; commands to the gateway on 9001."""
    patch = Patcher(1560, 1100)
    y = _header(patch, f"""sonibus -> Max: joint positions (rad; hands 0..1) and events from the OSC sink,
as this node of your installation file sends them (sonibus run show.toml):

[nodes.sound]
adapter = "osc"
subscribe = ["{robot}/joints/*", "{robot}/events/*"]
targets = ["127.0.0.1:9000"]""", 30, 15)
    udp = patch.obj("udpreceive 9000", 30, y)
    events = [f"/{robot}/events/{kind}" for kind in EVENTS]
    joints = [[f"/{robot}/joints/{j}" for j in chain] for chain in _chains(model)]
    found, y = ladder(patch, udp, 0, 30, y + ROW * 1.5, [events], 100)
    route, outlet, ox = found[events[0]]
    for kind, address in zip(EVENTS, events, strict=True):
        patch.connect(*found[address][:2], patch.obj(f"print {kind}", found[address][2], _y(patch, route) + ROW * 1.5))
    states = patch.obj("unpack s s", ox, _y(patch, route) + ROW * 2.5)
    patch.connect(route, outlet, states)
    sel = patch.obj("sel started stopped", ox, _y(patch, route) + ROW * 3.5)
    patch.connect(states, 1, sel)
    for i, what in enumerate(("a behavior started", "stopped")):
        bang = patch.button(ox + 160 + i * 140, _y(patch, route) + ROW * 3.5)
        patch.connect(sel, i, bang)
        patch.comment(what, ox + 188 + i * 140, _y(patch, route) + ROW * 3.5, 110)
    joint_routes, bottom = ladder(patch, route, len(events), 30, y + ROW * 1.5, joints, 100)
    found |= joint_routes
    for chain in joints:
        for address in chain:
            route, outlet, ox = found[address]
            number = patch.flonum(ox, _y(patch, route) + ROW * 1.5)
            patch.connect(route, outlet, number)
            patch.comment(address.rpartition("/")[2], ox, _y(patch, route) + ROW * 2.3, 100, fontsize=10.0)
    _sound(patch, robot, model, found[f"/{robot}/joints/HeadYaw"], 30, bottom)
    _commands(patch, robot, model, 800, 15)
    return patch


def _y(patch: Patcher, ident: str) -> float:
    return float(next(b["box"]["patching_rect"][1] for b in patch.boxes if b["box"]["id"] == ident))


def _sound(patch: Patcher, robot: str, model: RobotModel, head: tuple[str, int, float], x: float, y: float) -> None:
    """HeadYaw as the pitch of a sine, ramped over one frame as in docs/osc.md."""
    spec = model.joint("HeadYaw")
    patch.comment("HeadYaw -> pitch (200..800 Hz), a 10 ms ramp: one frame at 100 Hz. Click the speaker.",
                  x, y, 520)
    scale = patch.obj(f"scale {spec.min!r} {spec.max!r} 200. 800.", x, y + ROW)
    patch.connect(head[0], head[1], scale)
    ramp = patch.message("$1 10", x, y + ROW * 2)
    patch.connect(scale, 0, ramp)
    line = patch.obj("line~", x, y + ROW * 3)
    patch.connect(ramp, 0, line)
    sine = patch.obj("cycle~", x, y + ROW * 4)
    patch.connect(line, 0, sine)
    gain = patch.obj("*~ 0.1", x, y + ROW * 5)
    patch.connect(sine, 0, gain)
    dac = patch.add("ezdac~", (x, y + ROW * 6, 45, 45), 2, [])
    patch.connect(gain, 0, dac)
    patch.connect(gain, 0, dac, 1)


def _commands(patch: Patcher, robot: str, model: RobotModel, x: float, y: float) -> None:
    """Message boxes and sliders into one [udpsend] to the gateway."""
    y = _header(patch, f"""Max -> sonibus: commands through the OSC gateway; the robot's owner checks
each one like any other command (limits, behaviors, postures).

[nodes.remote]
adapter = "osc-gateway"
listen = "127.0.0.1:9001"

Each command is answered at /{robot}/reply/<verb> on the port it came from, where
[udpsend] does not listen: watch /{robot}/events/command on the left instead.""", x, y)
    cmd = f"/{robot}/cmd/"
    behaviors = list(LIBRARY)[:2]
    texts = [f'{cmd}say "hello from Max"', *(f"{cmd}behavior/run {b}" for b in behaviors), f"{cmd}behavior/stop",
             f"{cmd}posture Crouch 0.5", f"{cmd}posture StandInit 0.5"]
    sources = [patch.message(text, x, y + i * ROW) for i, text in enumerate(texts)]
    y += len(texts) * ROW
    sources.append(patch.message(f"{cmd}stop", x, y + 6, fontsize=24.0, bgcolor=[0.9, 0.2, 0.2, 1.0]))
    patch.comment("stops motion and speech at once", x + 280, y + 14, 220)
    y += ROW * 2.5
    for joint in SLIDERS:
        spec = model.joint(joint)
        patch.comment(f"{joint}: {spec.min:g} .. {spec.max:g} {spec.unit}", x, y, 300)
        slider = patch.add("slider", (x, y + 22, 200, 20), 1, [""], floatoutput=1, size=1.0, parameter_enable=0)
        scale = patch.obj(f"scale 0. 1. {spec.min!r} {spec.max!r}", x + 220, y + 22)
        patch.connect(slider, 0, scale)
        prepend = patch.obj(f"prepend {cmd}joints/set/{joint}", x + 220, y + 22 + ROW)
        patch.connect(scale, 0, prepend)
        sources.append(prepend)
        y += ROW * 3
    send = patch.obj("udpsend 127.0.0.1 9001", x, y)
    for source in sources:
        patch.connect(source, 0, send)


def pepperosc_patch(robot: str, model: RobotModel) -> Patcher:
    """PepperOSC's receivers: /pepperdata "/<Joint>" "/PositionSensor" value, /latency, /soundstart, /soundstop."""
    patch = Patcher(1400, 900)
    y = _header(patch, "\n".join((
        "PepperOSC's routing, for labs moving over: what its patches listened to on port 3005,",
        "as sonibus's pepperosc profile sends it:",
        "",
        "[nodes.pepperosc]",
        'adapter = "osc"',
        f'subscribe = ["{robot}/joints/*", "{robot}/events/behavior"]',
        'targets = ["127.0.0.1:3005"]',
        'profile = "pepperosc"')), 30, 15)
    udp = patch.obj("udpreceive 3005", 30, y)
    top = patch.obj("route /pepperdata /soundstart /soundstop", 30, y + ROW, 420)
    patch.connect(udp, 0, top)
    for i, word in enumerate(("soundstart", "soundstop")):
        ox = 30 + (i + 1) * 410 / 3
        bang = patch.button(ox, y + ROW * 2.2)
        patch.connect(top, i + 1, bang)
        patch.connect(top, i + 1, patch.obj(f"print {word}", ox + 30, y + ROW * 2.2))
    groups = [[f"/{j}" for j in chain] for chain in _chains(model)]
    found, _ = ladder(patch, top, 0, 30, y + ROW * 3.5, [*groups, ["/latency"]], 170)
    sensors = {}
    for group in groups:
        for address in group:
            route, outlet, ox = found[address]
            sensor = sensors[address] = patch.obj("route /PositionSensor", ox, _y(patch, route) + ROW * 1.2)
            patch.connect(route, outlet, sensor)
            patch.connect(sensor, 0, patch.flonum(ox, _y(patch, route) + ROW * 2.2))
            patch.comment(address[1:], ox + 64, _y(patch, route) + ROW * 2.2, 100, fontsize=10.0)
    route, outlet, ox = found["/latency"]
    ms = patch.obj("* 1000.", ox, _y(patch, route) + ROW * 1.2)
    patch.connect(route, outlet, ms)
    patch.comment("/latency: seconds between frames, in ms: the ramp time of [line], as PepperOSC's Pd patch "
                  "used it", ox + 70, _y(patch, route) + ROW * 1.2, 420)
    pack = patch.obj("pack 0. 10.", ox, _y(patch, route) + ROW * 2.4)
    patch.connect(ms, 0, pack, 1)
    patch.connect(sensors["/HeadYaw"], 0, pack)
    line = patch.obj("line 0.", ox, _y(patch, route) + ROW * 3.4)
    patch.connect(pack, 0, line)
    patch.connect(line, 0, patch.flonum(ox, _y(patch, route) + ROW * 4.4))
    patch.comment("HeadYaw, ramped from frame to frame", ox + 64, _y(patch, route) + ROW * 4.4, 260)
    return patch


def write(patch: Patcher, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(patch.document(), indent="\t") + "\n", encoding="utf-8")
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="pepper", help="the robot's bus name (default: pepper)")
    parser.add_argument("--output", type=Path, default=PATCHES, help="the patches folder to write into")
    args = parser.parse_args()
    model = load_model(args.robot.rstrip("0123456789"))
    write(sonibus_patch(args.robot, model), args.output / "max" / "sonibus.maxpat")
    write(pepperosc_patch(args.robot, model), args.output / "pepperosc" / "pepperosc.maxpat")


if __name__ == "__main__":
    main()
