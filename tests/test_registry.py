"""The adapter registry (entry-point group ``sonibus.adapters``) and the adapter lifecycle;
robot adapters checked for every verb, and names two packages register refused."""

from __future__ import annotations

import importlib
import io
import json
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from sonibus_testplugin import JsonLinesConfig, JsonLinesSink

from sonibus import schemas
from sonibus.adapters.console import ConsoleView
from sonibus.adapters.osc import OscSink
from sonibus.adapters.sim import SimRobot
from sonibus.bus import (
    Adapter,
    AdapterError,
    CommandError,
    ConfigError,
    RobotAdapter,
    config,
    decode,
    installed,
    keys,
    load_model,
    registry,
    runner,
    send_command,
)
from sonibus.bus.cli import Environment, Exit, main
from sonibus.bus.verbs import METHODS, RobotVerbs, missing

from .conftest import wait_for

BUILT_IN = {"sim": SimRobot, "osc": OscSink, "console": ConsoleView}


def test_available_lists_built_ins_and_the_plugin_without_importing():
    found = installed.available()
    assert {"sim", "osc", "console", "jsonl", "broken"} <= set(found)
    assert found["jsonl"].value == "sonibus_testplugin:JsonLinesSink"
    assert found["sim"].value == "sonibus.adapters.sim:SimRobot"


@pytest.mark.parametrize("name", sorted(BUILT_IN))
def test_load_built_in(name):
    assert registry.load(name) is BUILT_IN[name]


def test_load_plugin_returns_its_class():
    cls = registry.load("jsonl")
    assert cls is JsonLinesSink
    assert issubclass(cls, Adapter)
    assert cls.Config is JsonLinesConfig
    assert registry.summary(cls).startswith("Appends every sample")


def test_load_unknown_lists_installed_adapters():
    with pytest.raises(AdapterError) as caught:
        registry.load("nope")
    message = str(caught.value)
    assert "'nope'" in message
    for name in ("sim", "osc", "console", "jsonl"):
        assert name in message.partition("'nope'")[2], f"{name} not listed: {message}"
    assert "\n" not in message


def test_load_broken_names_it_and_why():
    with pytest.raises(AdapterError) as caught:
        registry.load("broken")
    message = str(caught.value)
    assert "'broken'" in message
    assert "DoesNotExist" in message  # what could not be imported
    assert "\n" not in message


def test_load_all_skips_broken_with_one_warning(caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    loaded = registry.load_all()
    assert "broken" not in loaded
    assert {name: loaded[name] for name in BUILT_IN} == BUILT_IN
    assert loaded["jsonl"] is JsonLinesSink
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1, [r.getMessage() for r in warnings]
    assert warnings[0].name == "sonibus.bus.registry"
    assert "'broken'" in warnings[0].getMessage()
    assert "skipped" in warnings[0].getMessage()


def test_adapter_lifecycle_start_twice_stop_twice_and_repr(net, tmp_path):
    out = tmp_path / "samples.jsonl"
    sink = JsonLinesSink(JsonLinesConfig(path=str(out), subscribe="pepper/joints/HeadYaw"), name="rec")
    assert repr(sink) == "<JsonLinesSink 'rec' new>"
    net.sim("pepper", rate_hz=50)
    bus = net.bus("rec-host")
    sink.start(bus)
    try:
        assert sink.state == "running"
        assert repr(sink) == "<JsonLinesSink 'rec' running>"
        wait_for(lambda: out.exists() and out.read_text().count("\n") >= 3, what="samples in the file")
        with pytest.raises(RuntimeError, match="running"):
            sink.start(bus)
        assert sink.state == "running"  # the failed second start changed nothing
        assert bus.alive(keys.node_token(bus.host, "rec"))
    finally:
        sink.stop()
    assert sink.state == "stopped"
    assert repr(sink) == "<JsonLinesSink 'rec' stopped>"
    sink.stop()  # a second stop is fine
    assert sink.state == "stopped"
    assert not [t for t in sink._threads if t.is_alive()]
    wait_for(lambda: not bus.alive(keys.node_token(bus.host, "rec")), what="the node's token to go")
    lines = out.read_text().splitlines()
    assert all(json.loads(line)["key"] == "pepper/joints/HeadYaw" for line in lines)
    with pytest.raises(RuntimeError, match="stopped"):
        sink.start(bus)  # a stopped adapter does not come back


def test_stop_before_start_is_fine():
    view = ConsoleView(name="view")
    view.stop()
    view.stop()
    assert view.state == "stopped"
    assert "stopped" in repr(view) and "'view'" in repr(view)


def test_adapter_takes_only_its_own_config(tmp_path):
    with pytest.raises(TypeError, match="JsonLinesConfig"):
        JsonLinesSink(ConsoleView.Config())


# -- robot adapters: every verb, checked when the registry loads them ----------------------------


@dataclass(frozen=True)
class TapeConfig:
    robot: str = "tape"


class Tape:
    """Every verb of ``RobotVerbs``; remembers what it was asked."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict[str, Any]]] = []

    def _did(self, verb: str, **args: Any) -> dict[str, Any]:
        self.calls.append((verb, args))
        return {"done": verb}

    def awareness(self, enabled: bool) -> dict[str, Any]:
        return self._did("awareness", enabled=enabled)

    def behavior_list(self) -> dict[str, Any]:
        return {"behaviors": ["wave"]}

    def behavior_run(self, name: str) -> dict[str, Any]:
        return self._did("behavior/run", name=name)

    def behavior_stop(self, name: str | None = None) -> dict[str, Any]:
        return self._did("behavior/stop", name=name)

    def joints_set(self, names: list[str], angles: list[float], speed: float) -> dict[str, Any]:
        return self._did("joints/set", names=names, angles=angles, speed=speed)

    def posture(self, name: str, speed: float) -> dict[str, Any]:
        return self._did("posture", name=name, speed=speed)

    def say(self, text: str, volume: float | None = None, speed: float | None = None) -> dict[str, Any]:
        return self._did("say", text=text, volume=volume, speed=speed)

    def stiffness(self, names: list[str], value: float) -> dict[str, Any]:
        return self._did("stiffness", names=names, value=value)

    def stop(self) -> dict[str, Any]:
        return self._did("stop")


class TapeRobot(RobotAdapter):
    """A robot of tape: a Pepper model that never moves, and verbs that remember."""

    Config = TapeConfig
    Verbs = Tape

    def _open(self) -> None:
        self.model = load_model("pepper")
        self.verbs = Tape()

    def behaviors(self) -> list[str]:
        return ["wave"]

    def _acquire(self) -> None:
        self.stopping.wait()


class Mute(Tape):
    """Tape without ``say``, and an ``awareness`` that does not take the request's ``enabled``."""

    say = None  # type: ignore[assignment]

    def awareness(self, on: bool) -> dict[str, Any]:  # type: ignore[override]
        return self._did("awareness", enabled=on)


class MuteRobot(TapeRobot):
    """A robot whose verbs miss one and get one wrong."""

    Verbs = Mute

    def _open(self) -> None:
        super()._open()
        self.verbs = Mute()


class NamelessRobot(RobotAdapter):
    """A robot that names no class for its verbs."""

    Config = TapeConfig

    def _open(self) -> None:
        self.model, self.verbs = load_model("pepper"), Tape()


@pytest.fixture
def install(tmp_path, monkeypatch):
    """Installs distributions for real: a ``<name>-1.0.dist-info`` folder with its
    entry points, on ``sys.path`` for the test only."""
    monkeypatch.syspath_prepend(str(tmp_path))

    def installed(package: str, adapters: dict[str, str], requires: tuple[str, ...] = ()) -> None:
        info = tmp_path / f"{package.replace('-', '_')}-1.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 1.0\n"
                                       + "".join(f"Requires-Dist: {r}\n" for r in requires))
        (info / "entry_points.txt").write_text(
            "[sonibus.adapters]\n" + "".join(f"{name} = {value}\n" for name, value in adapters.items()))
        importlib.invalidate_caches()

    return installed


def here(cls: type) -> str:
    return f"{__name__}:{cls.__name__}"


def test_the_verbs_protocol_names_every_verb_with_the_arguments_of_its_request():
    assert set(METHODS) == set(schemas.command_verbs())
    assert missing(RobotVerbs) == [] and missing(Tape) == []

    class Odd(Tape):
        def posture(self, name: str, speed: float, style: str) -> dict[str, Any]:  # type: ignore[override]
            return {}

        @staticmethod
        def stiffness(names: list[str], value: float) -> dict[str, Any]:
            return {}

    assert missing(Odd) == ["posture (needs 'style', not an argument of the request)"]


def test_a_robot_adapter_with_every_verb_loads_and_its_verbs_get_the_validated_requests(install, net):
    install("tape-robots", {"tape": here(TapeRobot)})
    assert registry.load("tape") is TapeRobot
    assert missing(Tape) == []
    robot = net.start(TapeRobot(name="tape"))
    client = net.bus("client")
    move = {"names": ["HeadYaw"], "angles": [0.25]}  # speed defaults to 0.3
    assert send_command(client, "tape", "joints/set", move) == {"done": "joints/set"}
    assert send_command(client, "tape", "say", {"text": "hello"}) == {"done": "say"}
    assert send_command(client, "tape", "behavior/list", {}) == {"behaviors": ["wave"]}
    assert send_command(client, "tape", "stop", ["whatever"]) == {"done": "stop"}  # stop runs whatever came
    with pytest.raises(CommandError) as refused:
        send_command(client, "tape", "posture", {"name": "Nowhere"})
    assert refused.value.code == "unknown_posture"
    assert robot.verbs.calls == [("joints/set", {"names": ["HeadYaw"], "angles": [0.25], "speed": 0.3}),
                                 ("say", {"text": "hello", "volume": None, "speed": None}), ("stop", {})]


def test_a_robot_adapter_that_lacks_a_verb_is_refused_when_loaded(install, tmp_path, caplog):
    install("mute-robots", {"mute": here(MuteRobot), "nameless": here(NamelessRobot)})
    with pytest.raises(AdapterError) as caught:
        registry.load("mute")
    message = str(caught.value)
    assert "adapter 'mute'" in message and "package 'mute-robots'" in message and "Mute" in message
    assert "say" in message and "awareness (takes no 'enabled')" in message and "\n" not in message
    assert "stop" not in message.partition("implement")[2]  # only what is missing
    with pytest.raises(AdapterError, match=r"adapter 'nameless'.*names no Verbs class"):
        registry.load("nameless")

    show = tmp_path / "show.toml"
    show.write_text('[nodes.pepper]\nadapter = "mute"\n')
    with pytest.raises(ConfigError) as refused:  # before any node starts
        runner.build(config.load(show))
    assert "show.toml" in str(refused.value) and "package 'mute-robots'" in str(refused.value)

    caplog.set_level(logging.WARNING, logger="sonibus")
    loaded = registry.load_all()
    assert "mute" not in loaded and "nameless" not in loaded and loaded["sim"] is SimRobot
    skipped = [r.getMessage() for r in caplog.records if "(skipped)" in r.getMessage()]
    assert any("'mute'" in m and "awareness" in m for m in skipped), skipped


def test_a_robot_adapter_built_without_the_registry_is_checked_when_it_starts(net):
    bus = net.bus("robots")
    with pytest.raises(TypeError, match=r"Mute does not implement awareness \(takes no 'enabled'\), say"):
        MuteRobot(name="mute").start(bus)
    with pytest.raises(TypeError, match=r"NamelessRobot: _open\(\) must set self.verbs .*\(none declared\)"):
        NamelessRobot(name="nameless").start(bus)  # the claim is given back: the next start claims the robot
    robot = net.start(TapeRobot(name="tape"), bus)
    assert send_command(net.bus("client"), "tape", "stop", {}) == {"done": "stop"}
    assert robot.state == "running"


def test_an_adapter_whose_extra_is_missing_is_listed_with_the_extra_and_warns_only_when_used(
        install, tmp_path, caplog):
    """Issue 19, item 9: a wheel without the naoqi extra warned on every command that
    naoqi-sim cannot be imported."""
    (tmp_path / "needy_robots.py").write_text("import nosuch_robot_sdk\n")
    install("needy-robots", {"needy": "needy_robots:Needy"},
            requires=("msgpack>=1", 'nosuch-robot-sdk==3.1; extra == "robot"'))
    install("broken-robots", {"flawed": "needy_robots:Needy"}, requires=("other-sdk>=1",))  # no extra: a fault
    caplog.set_level(logging.WARNING, logger="sonibus")
    lacking: dict[str, str] = {}
    loaded = registry.load_all(lacking)
    assert "needy" not in loaded and lacking == {"needy": "pip install 'needy-robots[robot]'"}
    warned = [r.getMessage() for r in caplog.records]
    assert not any("'needy'" in m for m in warned), warned
    assert any("'flawed'" in m and "nosuch_robot_sdk" in m for m in warned), warned
    with pytest.raises(AdapterError, match=r"adapter 'needy' needs the optional 'robot' dependencies "
                                           r"\(nosuch_robot_sdk\): pip install 'needy-robots\[robot\]'$"):
        registry.load("needy")  # what an installation file that uses it gets
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    assert main(["adapters"], env) == Exit.OK
    assert "needy        (not installed: pip install 'needy-robots[robot]')" in env.stdout.getvalue().splitlines()


def test_a_name_two_packages_register_is_refused_naming_both(install, caplog):
    install("tape-robots", {"sim": here(TapeRobot)})  # the built-in sim is package sonibus's
    install("more-robots", {"twin": here(TapeRobot)})
    install("twin-robots", {"twin": here(TapeRobot)})
    for name, packages in (("sim", ("'sonibus'", "'tape-robots'")), ("twin", ("'more-robots'", "'twin-robots'"))):
        with pytest.raises(AdapterError) as caught:
            registry.load(name)
        message = str(caught.value)
        assert f"adapter '{name}'" in message and all(p in message for p in packages), message
        assert "\n" not in message
        assert name not in installed.available()
    assert registry.entries()[1].keys() == {"sim", "twin"}
    caplog.set_level(logging.WARNING, logger="sonibus")
    loaded = registry.load_all()
    assert "sim" not in loaded and "twin" not in loaded and loaded["osc"] is OscSink
    skipped = [r.getMessage() for r in caplog.records if "more than one package" in r.getMessage()]
    assert len(skipped) == 2 and all(m.endswith("(skipped)") for m in skipped), skipped


def test_the_robot_adapter_example_of_the_docs_implements_every_verb_and_serves_them(install, net, tmp_path):
    docs = (Path(__file__).resolve().parent.parent / "docs" / "adapters.md").read_text()
    code = docs.partition("### Robot adapters")[2].partition("```python\n")[2].partition("```")[0]
    (tmp_path / "puppet.py").write_text(code)
    install("puppet", {"puppet": "puppet:Puppet"})
    cls = registry.load("puppet")
    del sys.modules["puppet"]  # imported from this test's folder only
    assert missing(cls.Verbs) == []
    robot = net.start(cls(name="puppet"))
    client = net.bus("client")
    _subscriber, frames = client.subscribe("puppet/frame")
    assert send_command(client, "puppet", "joints/set", {"names": ["HeadYaw"], "angles": [0.5]}) == {}
    head = robot.model.joint_names.index("HeadYaw")

    def turned() -> bool:
        item = frames.get(timeout=0.2)
        return item is not None and decode(item[1])["v"][head] == pytest.approx(0.5)

    wait_for(turned, what="a frame with the head turned")
    with pytest.raises(CommandError) as refused:
        send_command(client, "puppet", "say", {"text": "hello"})
    assert refused.value.code == "failed" and "speak" in refused.value.message
