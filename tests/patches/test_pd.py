"""The Pure Data patches (patches/pd, patches/pepperosc) run by headless Pd: fed by simulated
robots through a real OSC sink, commanding a robot through a real osc-gateway.

A test patch finds the abstractions by ``#X declare -path`` as a user's patch would; what Pd
prints (``[print NAME]``, errors, objects it could not create) is read from its output.
"""

from __future__ import annotations

import itertools
import re
import socket
from pathlib import Path

import pytest

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.osc.config import parse_target
from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import config, load_model, send_command
from sonibus.bus.runner import build

from ..conftest import free_port, wait_for
from ..osc.pd import Patch, errors, printed, start_pd
from ..osc.test_gateway import Watch
from ..osc.test_pepperosc import commander

pytestmark = pytest.mark.external

PATCHES = Path(__file__).resolve().parents[2] / "patches"
PD, PEPPEROSC = PATCHES / "pd", PATCHES / "pepperosc"
PEPPER, NAO = load_model("pepper"), load_model("nao")
YES = "animations/Stand/Gestures/Yes_1"
HEY = "animations/Stand/Gestures/Hey_1"
EVENT_OUTLETS = ("behavior", "speech", "posture", "connection", "command", "other")


class Declared(Patch):
    """A test patch that finds the abstractions in ``folders``: ``#X declare -path``
    right after the canvas line, where Pd saves it."""

    def __init__(self, *folders: Path) -> None:
        super().__init__()
        self._folders = folders

    def text(self) -> str:
        head, rest = super().text().split("\n", 1)
        return "\n".join([head, *(f"#X declare -path {atom(folder)};" for folder in self._folders), rest])


def atom(path: Path | str) -> str:
    """A path as one Pd atom (Pd 0.51+ reads an escaped space as part of the symbol)."""
    return str(path).replace(" ", "\\ ")


def printer(patch: Patch, source: int, name: str, outlet: int = 0) -> None:
    patch.connect(source, outlet, patch.obj("print", name))


def bound(port: int) -> int:
    """UDP sockets bound to ``port`` on this machine (Linux: /proc/net/udp, udp6)."""
    rows = [row.split() for table in ("udp", "udp6") for row in Path(f"/proc/net/{table}").read_text().splitlines()[1:]]
    return sum(int(row[1].rsplit(":", 1)[1], 16) == port for row in rows)


def floats(process, name: str) -> list[float]:
    return [float(v) for v in printed(process, name)]


def sink(net, port: int, *subscribe: str, **settings) -> OscSink:
    config = OscSinkConfig(subscribe=subscribe, targets=(f"127.0.0.1:{port}",), **settings)
    return net.start(OscSink(config, name="sound"))


def turn(values: list[float], target: float) -> list[float]:
    """The values from the first one that left the start up to the first at ``target``."""
    moving = [i for i, v in enumerate(values) if v != values[0]]
    end = next(i for i, v in enumerate(values) if v == pytest.approx(target, abs=1e-5))
    return values[moving[0] - 1:end + 1]


def test_joints_and_events_reach_the_abstractions_through_one_port(net, spawn, tmp_path):
    """Two joints of pepper, one of nao and pepper's events on one port, through one socket:
    Pd 0.53 lets a second [netreceive] bind the same port without a word, and only the last
    one bound receives (the others fall silent). Each robot's values only where it is named."""
    port = free_port(socket.SOCK_DGRAM)
    patch = Declared(PD)
    printer(patch, patch.obj("sonibus-joint", "HeadYaw", "pepper", port), "HeadYaw")
    printer(patch, patch.obj("sonibus-joint", "RShoulderPitch", "pepper", port), "RShoulderPitch")
    printer(patch, patch.obj("sonibus-joint", "HeadYaw", "nao", port), "naoHeadYaw")
    events = patch.obj("sonibus-events", "pepper", port)
    for outlet, name in enumerate(EVENT_OUTLETS):
        printer(patch, events, name, outlet)
    pd = start_pd(spawn, tmp_path, patch)
    sink(net, port, "*/joints/*", "*/events/*")
    net.sim("pepper", rate_hz=50)
    net.sim("nao", rate_hz=50)
    bus = commander(net)
    commander(net, "nao")

    wait_for(lambda: printed(pd, "HeadYaw") and printed(pd, "naoHeadYaw"), what="HeadYaw of both robots in Pd")
    assert floats(pd, "HeadYaw")[0] == pytest.approx(PEPPER.posture("StandInit")["HeadYaw"], abs=1e-5)
    assert floats(pd, "naoHeadYaw")[0] == pytest.approx(NAO.posture("StandInit")["HeadYaw"], abs=1e-5)
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.5], "speed": 0.5})
    send_command(bus, "nao", "joints/set", {"names": ["HeadYaw"], "angles": [-0.5], "speed": 0.5})
    wait_for(lambda: "0.5" in printed(pd, "HeadYaw") and "-0.5" in printed(pd, "naoHeadYaw"),
             what="HeadYaw 0.5 (pepper) and -0.5 (nao) printed by Pd")

    heads, naos = turn(floats(pd, "HeadYaw"), 0.5), turn(floats(pd, "naoHeadYaw"), -0.5)
    assert heads == sorted(heads) and naos == sorted(naos, reverse=True), "a robot's values mixed with the other's"
    assert len(set(heads)) > 3, f"HeadYaw did not move through intermediate values: {heads}"
    assert all(a != b for a, b in itertools.pairwise(heads)), f"a frame printed twice: {heads}"
    assert bound(port) == 1, "one [netreceive] listens for all of them"
    limits = PEPPER.joint("HeadYaw")
    assert all(limits.min <= v <= limits.max for v in floats(pd, "HeadYaw"))
    shoulder, still = floats(pd, "RShoulderPitch"), PEPPER.posture("StandInit")["RShoulderPitch"]
    assert len(shoulder) >= len(heads) and shoulder == pytest.approx([still] * len(shoulder), abs=1e-5)

    send_command(bus, "pepper", "behavior/run", {"name": YES})
    wait_for(lambda: f"list {YES} stopped" in printed(pd, "behavior"), timeout=6, what="the behavior's end in Pd")
    assert printed(pd, "behavior") == [f"list {YES} started", f"list {YES} stopped"]
    assert "list behavior/run 1" in printed(pd, "command")
    assert errors(pd) == []


def opener(patch: Patch, path: Path) -> None:
    """At load, open the patch file ``path`` as a user would (``; pd open NAME DIR``)."""
    message = patch.obj("list", "append", "open", atom(path.name), atom(path.parent))
    patch.chain(patch.obj("loadbang"), message, patch.obj("list", "trim"), patch.obj("s", "pd"))


def test_another_abstraction_takes_the_port_over_when_the_listening_one_closes(net, spawn, tmp_path):
    """Two patches with a [sonibus-joint] each: the first opened listens for both; closed, the
    other takes the port over (its once-a-second check) and its values keep coming."""
    port, control = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    for name in ("first", "second"):
        patch = Declared(PD)
        printer(patch, patch.obj("sonibus-joint", "HeadYaw", "pepper", port), name)
        (tmp_path / f"{name}.pd").write_text(patch.text(), encoding="utf-8")
    patch = Patch()
    opener(patch, tmp_path / "first.pd")
    opener(patch, tmp_path / "second.pd")
    command = patch.chain(patch.obj("netreceive", "-u", control), patch.obj("t", "a", "a"))
    patch.connect(command, 0, patch.obj("print", "control"))  # after the close has run
    close = patch.obj("route", "close")
    patch.connect(command, 1, close)
    patch.chain(close, patch.obj("list", "append", "menuclose", 1), patch.obj("list", "trim"),
                patch.obj("s", "pd-first.pd"))
    pd = start_pd(spawn, tmp_path, patch)
    sink(net, port, "pepper/joints/*")
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    wait_for(lambda: printed(pd, "first") and printed(pd, "second"), what="HeadYaw in both patches")
    assert bound(port) == 1

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as fudi:
        fudi.sendto(b"close;\n", ("127.0.0.1", control))
    wait_for(lambda: "control: close" in pd.lines, what="the first patch closed")
    closed = len(printed(pd, "first"))
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.5], "speed": 0.5})
    wait_for(lambda: "0.5" in printed(pd, "second"), what="HeadYaw 0.5 in the second patch")
    assert len(printed(pd, "first")) == closed and bound(port) == 1
    assert errors(pd) == []


def hand_heights(process) -> list[float]:
    """z of each right-hand position printed."""
    return [float(line.split()[-1]) for line in printed(process, "handR")]


def test_derived_values_reach_the_abstraction(net, spawn, tmp_path):
    port = free_port(socket.SOCK_DGRAM)
    patch = Declared(PD)
    printer(patch, patch.obj("sonibus-derived", "hand", "R", "pepper", port), "handR")
    printer(patch, patch.obj("sonibus-derived", "qom", "RArm", "pepper", port), "qomRArm")
    pd = start_pd(spawn, tmp_path, patch)
    sink(net, port, "pepper/derived/hand/*", "pepper/derived/qom/*")
    net.start(Features(FeaturesConfig(robots="pepper"), name="features"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)

    wait_for(lambda: printed(pd, "handR") and printed(pd, "qomRArm"), what="derived values in Pd")
    start = hand_heights(pd)[0]
    send_command(bus, "pepper", "behavior/run", {"name": HEY})
    wait_for(lambda: max(hand_heights(pd)) > start + 0.3, timeout=6, what="the right hand waving up high")
    hands = [[float(x) for x in line.split()] for line in printed(pd, "handR")]
    assert {len(h) for h in hands} == {3}, "x y z"
    # The box of every reachable right-hand position (docs/features.md).
    assert all(-0.33 <= x <= 0.31 and -0.52 <= y <= 0.02 and -0.28 <= z <= 0.45 for x, y, z in hands)
    assert max(floats(pd, "qomRArm")) > 1, "the arm's quantity of motion while waving (rad/s)"
    assert errors(pd) == []


def test_send_commands_the_robot_through_the_gateway_and_prints_its_replies(net, spawn, tmp_path):
    """Commands typed as a Pd user would (here arriving as FUDI on a control port, as
    message boxes would send them) move the simulated robot; the replies reach the outlet."""
    net.sim("pepper", rate_hz=50)
    gate_port, control = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{gate_port}"), name="gate"))
    patch = Declared(PD)
    control_in = patch.obj("netreceive", "-u", control)
    printer(patch, patch.chain(control_in, patch.obj("sonibus-send", "pepper", "127.0.0.1", gate_port)), "reply")
    pd = start_pd(spawn, tmp_path, patch)
    head, speech = Watch(net, "pepper/joints/HeadYaw"), Watch(net, "pepper/events/speech")

    def replied(start: str) -> bool:
        return any(reply.startswith(start) for reply in printed(pd, "reply"))

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as fudi:
        def type_in(message: str) -> None:
            fudi.sendto(f"{message};\n".encode(), ("127.0.0.1", control))

        type_in("joints/set/HeadYaw 0.3")
        wait_for(lambda: replied("joints set HeadYaw 1 {"), what="the joints/set reply in Pd")
        wait_for(lambda: head.all() and head.seen[-1]["v"] == pytest.approx(0.3, abs=1e-6), what="HeadYaw at 0.3")
        type_in("say hello world")
        wait_for(lambda: replied("say 1 {"), what="the say reply in Pd")
        wait_for(lambda: any(e["text"] == "hello world" for e in speech.all()), what="the robot speaking")
        type_in("joints/set/HeadYaw 3")
        wait_for(lambda: replied("joints set HeadYaw 0 out_of_range"), what="the refusal of 3 rad in Pd")
        type_in("stop")
        wait_for(lambda: replied("stop 1 {"), what="the stop reply in Pd")
    assert head.steady() == pytest.approx(0.3, abs=1e-6), "3 rad was refused: the head stayed"
    assert len(printed(pd, "reply")) == 4, printed(pd, "reply")
    assert errors(pd) == []


def test_help_patches_and_the_pepperosc_receiver_open_and_work(net, spawn, tmp_path):
    """Every help patch opened in one Pd, as a user opens them, on the default ports (9000,
    and 3005 for PepperOSC's receiver): every object exists, they share port 9000, and the
    events help prints a behavior a sink sends to 9000."""
    helps = sorted(PD.glob("*-help.pd"))
    abstractions = sorted(p.stem for p in PD.glob("*.pd") if not p.stem.endswith("-help"))
    assert [h.name.removesuffix("-help.pd") for h in helps] == abstractions, "a help patch per abstraction"
    taken = [port for port in (9000, 3005) if bound(port)]
    assert not taken, f"UDP port(s) {taken} in use on this machine (a Pd or an OSC receiver running?): the " \
                      f"help patches listen on 9000 and 3005 as a user opens them — stop what holds them"
    patch = Patch()
    for path in [*helps, PEPPEROSC / "pepperosc-receiver.pd"]:
        opener(patch, path)
    pd = start_pd(spawn, tmp_path, patch)  # fails on an error printed while they open (a port in use, say)
    sink(net, 9000, "pepper/events/*")
    net.sim("pepper", rate_hz=50)
    send_command(commander(net), "pepper", "behavior/run", {"name": YES})
    wait_for(lambda: f"list {YES} stopped" in printed(pd, "behavior"), timeout=6,
             what="the events help printing the behavior")
    assert f"behavior {YES} started" in printed(pd, "event")  # the [sonibus-receive] help
    assert bound(9000) == 1
    assert errors(pd) == []


def test_pepperosc_receiver_ramps_joints_and_passes_the_sound_cues(net, spawn, tmp_path):
    port = free_port(socket.SOCK_DGRAM)
    patch = Declared(PEPPEROSC)
    patch.obj("pepperosc-receiver", port)
    for name in ("HeadYaw", "soundstart", "soundstop"):
        patch.chain(patch.obj("r", f"pepperosc-{name}"), patch.obj("print", name))
    pd = start_pd(spawn, tmp_path, patch)
    sink(net, port, "pepper/joints/*", "pepper/events/*", profile="pepperosc")
    net.sim("pepper", rate_hz=50)
    bus = commander(net)

    wait_for(lambda: printed(pd, "HeadYaw"), what="HeadYaw from the receiver")
    assert floats(pd, "HeadYaw")[0] == pytest.approx(PEPPER.posture("StandInit")["HeadYaw"], abs=1e-5)
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.5], "speed": 0.5})
    wait_for(lambda: "0.5" in printed(pd, "HeadYaw"), what="HeadYaw ramped to 0.5")
    heads = turn(floats(pd, "HeadYaw"), 0.5)
    assert heads == sorted(heads) and len(set(heads)) > 3, heads
    send_command(bus, "pepper", "behavior/run", {"name": YES})
    wait_for(lambda: printed(pd, "soundstop"), timeout=6, what="soundstop after the behavior")
    lines = list(pd.lines)
    assert printed(pd, "soundstart") == ["1"] and printed(pd, "soundstop") == ["1"]
    assert lines.index("soundstart: 1") < lines.index("soundstop: 1")
    assert errors(pd) == []


def test_the_readme_installations_build_and_send_where_the_patches_listen():
    """Every TOML block of the two READMEs builds (each node's options valid); the sinks send
    to 9000 (the abstractions' default) and 3005 with the pepperosc profile (the receiver's),
    and the gateway listens on 9001 ([sonibus-send]'s default)."""
    sends, listens = set(), set()
    for readme in (PD / "README.md", PEPPEROSC / "README.md"):
        for block in re.findall(r"```toml\n(.*?)```", readme.read_text(encoding="utf-8"), re.S):
            for adapter in build(config.parse(block, str(readme))):
                if isinstance(adapter, OscSink):
                    sends |= {(parse_target(t.to)[1], t.profile) for t in adapter.config.resolved_targets()}
                elif isinstance(adapter, OscGateway):
                    listens.add(parse_target(adapter.config.listen)[1])
    assert sends == {(9000, "sonibus"), (3005, "pepperosc")} and listens == {9001}
