"""Installation files: golden cases under ``tests/cases/config/``.

``valid-*.toml`` must load and build. ``invalid-*.toml`` start with header
comments that say what the error must contain:

    # error: <fragment of the message>        (required)
    # table: [nodes.sound]                    (the table the error is in, if any)
    # key: tagets                             (the key the error is about, if any)
    # line: 9                                 (the line the message must name, if any)

Valid files may say ``# nodes: a, b`` (the node names, in order).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import pytest

from sonibus.adapters.console import ConsoleView
from sonibus.adapters.osc import OscSink
from sonibus.adapters.sim import SimRobot
from sonibus.bus import Adapter, BusConfig, ConfigError, Installation, load_installation
from sonibus.bus.config import parse
from sonibus.bus.runner import build

CASES = Path(__file__).parent / "cases" / "config"
VALID = sorted(CASES.glob("valid-*.toml"))
INVALID = sorted(CASES.glob("invalid-*.toml"))
HEADER_KEYS = ("error", "table", "key", "line", "nodes")


def header(path: Path) -> dict[str, str]:
    """The ``# name: value`` comments at the top of a case file."""
    found: dict[str, str] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        name, sep, value = line[1:].strip().partition(":")
        if sep and name in HEADER_KEYS:
            found[name] = value.strip()
    return found


def config_error(path: Path, only: list[str] | None = None) -> str:
    """The message of the ``ConfigError`` that loading and building ``path`` raises."""
    with pytest.raises(ConfigError) as caught:
        build(load_installation(path), only)
    return str(caught.value)


def test_the_golden_cases_are_there():
    assert len(VALID) >= 3
    assert len(INVALID) >= 15
    for path in INVALID:
        assert header(path).get("error"), f"{path.name}: first line must be '# error: <fragment>'"


@pytest.mark.parametrize("path", [p for p in INVALID if {"line", "key"} <= set(header(p))], ids=lambda p: p.stem)
def test_golden_case_line_sets_its_key(path):
    """A declared line really sets the declared key (so the cases cannot drift)."""
    expected = header(path)
    line = path.read_text(encoding="utf-8").splitlines()[int(expected["line"]) - 1]
    assert expected["key"] in line, f"{path.name}: line {expected['line']} does not mention {expected['key']}"


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
def test_valid_file_loads_and_builds(path):
    installation = load_installation(path)
    assert isinstance(installation, Installation)
    assert installation.path == str(path)
    assert isinstance(installation.bus, BusConfig)
    installation.bus.to_zenoh()  # every bus setting is accepted by Zenoh too
    adapters = build(installation)
    assert [a.name for a in adapters] == list(installation.nodes)
    assert all(isinstance(a, Adapter) and a.state == "new" for a in adapters)
    names = header(path).get("nodes")
    if names:
        assert list(installation.nodes) == [n.strip() for n in names.split(",")]


def test_valid_full_file_values_are_typed():
    installation = load_installation(CASES / "valid-full.toml")
    bus = installation.bus
    assert bus.mode == "client"
    assert bus.connect == ("tcp/192.168.1.10:7447", "tcp/192.168.1.11:7447")
    assert bus.multicast is False
    assert bus.namespace == "show1"
    assert bus.options == {"transport/link/tx/lease": 2000}
    pepper, sound, view, recorder = build(installation)
    assert isinstance(pepper, SimRobot) and isinstance(sound, OscSink) and isinstance(view, ConsoleView)
    assert pepper.config.rate_hz == 50.0 and isinstance(pepper.config.rate_hz, float)
    assert sound.config.targets == ("127.0.0.1:3005", "localhost:3002")
    assert view.config.joints == ("HeadYaw", "LHand")
    assert type(recorder).__name__ == "JsonLinesSink"
    assert recorder.config.subscribe == "**"


def test_shipped_demo_file_is_valid():
    text = resources.files("sonibus.adapters").joinpath("demo.toml").read_text(encoding="utf-8")
    adapters = build(parse(text, "demo.toml"))
    assert [type(a).__name__ for a in adapters] == ["SimRobot", "OscSink", "ConsoleView"]


@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.stem)
def test_invalid_file_names_file_table_key_and_problem(path):
    expected = header(path)
    message = config_error(path)
    assert "\n" not in message, f"not one line: {message!r}"
    assert path.name in message, f"file not named: {message}"
    assert expected["error"] in message, f"expected {expected['error']!r} in: {message}"
    if "table" in expected:
        assert expected["table"] in message, f"table {expected['table']} not named: {message}"
    if "key" in expected:
        assert expected["key"] in message, f"key {expected['key']!r} not named: {message}"
    if "line" in expected:
        assert f"line {expected['line']}" in message, f"line {expected['line']} not named: {message}"


def test_unknown_adapter_lists_installed_adapters():
    message = config_error(CASES / "invalid-unknown-adapter.toml")
    listed = message.rpartition(":")[2]
    for name in ("sim", "osc", "console", "jsonl"):
        assert name in listed, f"{name} not listed in: {message}"


def test_unknown_key_lists_known_keys():
    message = config_error(CASES / "invalid-unknown-key.toml")
    for key in ("subscribe", "targets", "address"):
        assert key in message


def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "nowhere" / "show.toml"
    with pytest.raises(ConfigError) as caught:
        load_installation(path)
    assert str(path) in str(caught.value)
    assert "no such file" in str(caught.value)


def test_unreadable_path_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError) as caught:
        load_installation(tmp_path)  # a directory
    assert str(tmp_path) in str(caught.value)


def test_only_selects_nodes_in_the_order_given():
    installation = load_installation(CASES / "valid-full.toml")
    adapters = build(installation, ["view", "pepper"])
    assert [(a.name, type(a)) for a in adapters] == [("view", ConsoleView), ("pepper", SimRobot)]


def test_only_with_unknown_node_is_an_error_naming_it():
    path = CASES / "valid-full.toml"
    message = config_error(path, ["sound", "lights"])
    assert "'lights'" in message
    assert path.name in message
    assert "pepper" in message  # the nodes there are
    assert "\n" not in message


def test_errors_come_before_anything_is_built():
    """A bad node anywhere fails ``build`` even when a good node comes first."""
    text = '[nodes.view]\nadapter = "console"\n\n[nodes.pepper]\nadapter = "sim"\nrate_hz = -5\n'
    with pytest.raises(ConfigError):
        build(parse(text, "show.toml"))
    assert [a.name for a in build(parse(text, "show.toml"), ["view"])] == ["view"]


@pytest.mark.parametrize("selection", [{"only": ["robot"]}, {"host": "spare-pc"}], ids=["only", "host"])
def test_two_owners_are_found_among_all_nodes_not_only_the_selected(selection):
    """Two machines each running one owner of 'pepper' would collide on the bus."""
    path = CASES / "invalid-two-owners.toml"
    with pytest.raises(ConfigError, match=r"robot 'pepper' has two owners, \[nodes.robot\].*\[nodes.spare\]"):
        build(load_installation(path), **selection)


def test_owner_check_skips_nodes_that_cannot_be_built_elsewhere():
    """A node for another machine whose adapter is not installed here, or whose options are
    wrong, is that machine's error: this one still runs its own nodes."""
    text = ('[nodes.robot]\nadapter = "sim"\n\n[nodes.elsewhere]\nadapter = "not-installed-here"\n\n'
            '[nodes.other]\nadapter = "sim"\nrate_hz = -5\n')
    assert [a.name for a in build(parse(text, "show.toml"), ["robot"])] == ["robot"]


def test_owned_robots_is_a_hook_of_the_adapter_class():
    """The core knows no adapter by name: each class says which robots a config owns."""
    from sonibus.adapters.recorder.replay import Replay, ReplayConfig
    from sonibus.adapters.sim import SimConfig

    assert Adapter.owned_robots(None) == ()
    assert ConsoleView.owned_robots(ConsoleView.Config()) == ()
    assert SimRobot.owned_robots(SimConfig(robot="nao2")) == ("nao2",)
    assert Replay.owned_robots(ReplayConfig("take.mcap", rename={"pepper": "pepper_replay"})) == ("pepper_replay",)
    assert Replay.owned_robots(ReplayConfig("take.mcap")) == ()  # its robots are in the file, known at start


def test_a_bus_table_error_names_the_line_of_a_sub_table():
    text = '[bus]\nmulticast = false\n\n[bus.options]\n"scouting/multicast/enabled" = "no"\n\n' \
           '[nodes.view]\nadapter = "console"\n'
    with pytest.raises(ConfigError) as caught:
        parse(text, "show.toml")
    message = str(caught.value)
    assert message.startswith("show.toml [bus] line 4: key 'options': Zenoh refuses scouting/multicast/enabled")
    assert "expected a boolean" in message and ".rs:" not in message


@pytest.mark.parametrize(("role", "endpoint"), [
    ("connect", "tcp/192.168.1.10:7447"), ("connect", "tcp/robot.local:7447"), ("connect", "tcp/[::1]:7447"),
    ("connect", "tcp/[fe80::1%eth0]:7447"), ("connect", "tls/10.0.0.5:7447"), ("connect", "udp/224.0.0.224:7447"),
    ("connect", "tcp/10.0.0.5:7447#iface=eth0"), ("connect", "quic/10.0.0.5:65535"), ("listen", "tcp/0.0.0.0:0"),
    ("listen", "tcp/[::]:7447"), ("listen", "ws/0.0.0.0:8080"), ("listen", "unixsock-stream//tmp/sonibus.sock"),
])
def test_endpoints_zenoh_takes_are_accepted(role, endpoint):
    BusConfig(**{role: (endpoint,)})


@pytest.mark.parametrize(("role", "endpoint", "why"), [
    ("connect", "tcp/127.0.0.1:0", "port 0 is out of range — give one from 1 to 65535"),
    ("connect", "tcp/127.0.0.1:65536", "port 65536 is out of range"),
    ("listen", "tcp/0.0.0.0:70000", "port 70000 is out of range — give one from 0 (any free port) to 65535"),
    ("listen", "tcp/0.0.0.0:http", "port 'http' is not a number"),
    ("connect", "tcp/10.0.0.5", "no port"),
    ("connect", "tcp/:7447", "no host"),
    ("connect", "tcp/::1:7447", "an IPv6 address goes in brackets, e.g. tcp/[::1]:7447"),
    ("connect", "tcp/[::g]:7447", "'::g' is not an IPv6 address"),
    ("connect", "tcp/300.1.1.1:7447", "'300.1.1.1' is not an IPv4 address"),
    ("connect", "tcp/my robot:7447", "'my robot' is not a host name or an IP address"),
    ("connect", "10.0.0.5:7447", "is not an endpoint — write <protocol>/<host>:<port>"),
    ("listen", "tpc/0.0.0.0:7447", "unknown protocol 'tpc'"),
])
def test_impossible_endpoints_are_refused_naming_the_key(role, endpoint, why):
    with pytest.raises(ConfigError) as caught:
        BusConfig(**{role: (endpoint,)})
    assert str(caught.value).startswith(f"key '{role}': '{endpoint}'")
    assert why in str(caught.value)
