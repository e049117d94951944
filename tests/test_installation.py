"""Installations across machines, on loopback: nodes picked by host, per-host bus
settings, Zenoh's options from [bus], `sonibus router`, a client waiting for its
router, presence in `sonibus nodes`, and sinks hearing of a robot's loss and return.
(The same across real network namespaces: tests/net/.)"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import BusConfig, ConfigError, keys
from sonibus.bus.config import parse
from sonibus.bus.runner import build

from .conftest import SONIBUS, free_port, run_cli, wait_for
from .osc.pd import Datagrams

THREE_MACHINES = """
[bus]
users_file = "users.txt"
tls = { root_ca = "certs/ca.pem" }

[bus.hosts.robot-pc]
user = "robot"
password = "robot-secret"
tls = { root_ca = "certs/ca.pem", cert = "certs/robot.pem", key = "certs/robot-key.pem", mutual = true }

[nodes.robot]
adapter = "sim"
host = "robot-pc"

[nodes.sound]
adapter = "osc"
host = "sound-pc"
targets = ["127.0.0.1:9000"]

[nodes.console]
adapter = "console"
"""


def test_each_host_runs_its_own_nodes_and_the_unpinned_ones():
    installation = parse(THREE_MACHINES, "/shows/museum/show.toml")
    assert [a.name for a in build(installation, host="robot-pc")] == ["robot", "console"]
    assert [a.name for a in build(installation, host="sound-pc")] == ["sound", "console"]
    assert [a.name for a in build(installation, only=["sound"], host="robot-pc")] == ["sound"]
    assert build(installation, host="robot-pc")[0].kind == "sim"


def test_a_host_with_no_node_is_told_which_hosts_there_are():
    installation = parse(THREE_MACHINES.replace("[nodes.console]\nadapter = \"console\"\n", ""), "show.toml")
    with pytest.raises(ConfigError, match="no node for host 'elsewhere' — hosts: robot-pc, sound-pc"):
        build(installation, host="elsewhere")


def test_bus_settings_per_host_and_paths_next_to_the_file():
    bus = parse(THREE_MACHINES, "/shows/museum/show.toml").bus
    robot = bus.for_host("robot-pc").entries()
    assert robot["transport/auth/usrpwd/user"] == "robot"
    assert robot["transport/auth/usrpwd/dictionary_file"] == "/shows/museum/users.txt"
    assert robot["transport/link/tls/root_ca_certificate"] == "/shows/museum/certs/ca.pem"
    assert robot["transport/link/tls/listen_certificate"] == "/shows/museum/certs/robot.pem"
    assert robot["transport/link/tls/enable_mtls"] is True
    sound = bus.for_host("sound-pc").entries()
    assert "transport/auth/usrpwd/user" not in sound
    assert sound["transport/link/tls/root_ca_certificate"] == "/shows/museum/certs/ca.pem"


def test_installation_defaults_detect_loss_in_two_seconds_and_retry_every_second():
    entries = BusConfig().entries()
    assert entries["transport/link/tx/lease"] == 1500
    assert entries["connect/retry"]["period_max_ms"] == 1000
    tuned = BusConfig(lease_ms=10000, reconnect_ms=3000).entries()
    assert tuned["transport/link/tx/lease"] == 10000 and tuned["connect/retry"]["period_max_ms"] == 3000
    BusConfig(access_control={"default_permission": "deny"}).to_zenoh()  # Zenoh takes the ACL as is
    assert BusConfig(access_control={"default_permission": "deny"}).entries()["access_control"]["enabled"]


@pytest.mark.parametrize(("options", "why"), [
    ({"user": "robot"}, "user and password go together"),
    ({"tls": {"cert": "a.pem", "key": "a.key"}}, "needs root_ca"),
    ({"tls": {"root_ca": "ca.pem", "cert": "a.pem"}}, "cert and key go together"),
    ({"reconnect_ms": 10}, "reconnect_ms"),
])
def test_bad_bus_settings_name_the_key(options, why):
    with pytest.raises(ConfigError, match=why):
        BusConfig(**options)


def test_router_joins_clients_and_a_client_waits_for_its_router(tmp_path, spawn, net):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmode = "client"\nmulticast = false\nconnect = ["{endpoint}"]\n\n'
                    '[nodes.robot]\nadapter = "sim"\nrate_hz = 20\n')
    robot = spawn(SONIBUS, "run", str(show), collect=True, merge=True)  # before the router: it waits
    wait_for(lambda: any("waiting for a router at" in line for line in robot.lines), timeout=10,
             what="the client to wait for its router")
    router = spawn(SONIBUS, "router", "--listen", endpoint, "--no-multicast", collect=True)
    wait_for(lambda: any("listening on" in line for line in router.lines), what="the router")
    watcher = net.bus("watch")  # a peer of the test network, not of the router's
    result = run_cli("send", "pepper", "stop", "--mode", "client", "--connect", endpoint, "--no-multicast")
    deadline = time.monotonic() + 10
    while result.returncode != 0 and time.monotonic() < deadline:  # until the robot's client has joined
        result = run_cli("send", "pepper", "stop", "--mode", "client", "--connect", endpoint, "--no-multicast")
    assert result.returncode == 0, result.stderr
    assert not watcher.alive(keys.robot_token("pepper")), "another network does not see it"
    wait_for(lambda: any("running robot" in line for line in robot.lines), what="the robot node running")
    robot.stop(signal.SIGTERM, timeout=3)
    assert not any("Traceback" in line for line in robot.lines)
    assert router.stop(signal.SIGINT, timeout=3)[0] in (0, 130)


def test_a_client_waiting_for_its_router_still_ends_on_sigterm(tmp_path, spawn):
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmode = "client"\nmulticast = false\nconnect = ["tcp/127.0.0.1:{free_port()}"]\n\n'
                    '[nodes.robot]\nadapter = "sim"\n')
    robot = spawn(SONIBUS, "run", str(show), collect=True, merge=True)
    wait_for(lambda: any("waiting for a router at" in line for line in robot.lines), timeout=10, what="waiting")
    code, _, _ = robot.stop(signal.SIGTERM, timeout=3)
    assert code == 130 and not any("Traceback" in line for line in robot.lines)


def test_a_client_without_router_fails_at_once_for_one_shot_commands():
    started = time.monotonic()
    result = run_cli("send", "pepper", "stop", "--mode", "client", "--connect", f"tcp/127.0.0.1:{free_port()}",
                     "--no-multicast")
    assert result.returncode == 2 and "cannot open the bus" in result.stderr
    assert time.monotonic() - started < 10  # start-up included; one waiting for a router would never end


def test_nodes_lists_adapter_robots_and_uptime(net):
    net.sim("pepper")
    result = run_cli("nodes", *net.cli_args())
    line = next(line for line in result.stdout.splitlines() if "sim-pepper" in line and "node" in line)
    assert " sim " in line and "SimRobot" not in line  # the adapter's name, as in the installation file
    assert "owns pepper" in line and " up " in line


def test_osc_sink_sends_connection_lost_and_connected_with_the_robot(net):
    receiver = Datagrams()
    try:
        net.start(OscSink(OscSinkConfig(subscribe=("pepper/events/*",), targets=(receiver.target,)), name="sound"))
        robot = net.sim("pepper", rate_hz=20)

        def states():
            return [d.split(b",s\0\0", 1)[1].rstrip(b"\0").decode() for d in receiver.data()
                    if d.startswith(b"/pepper/events/connection\0")]

        wait_for(lambda: states() == ["connected"], what="connected")
        robot.stop()
        wait_for(lambda: states() == ["connected", "lost"], what="lost, at once, when the robot leaves")
        net.sim("pepper", rate_hz=20)
        wait_for(lambda: states() == ["connected", "lost", "connected"], what="connected again")
    finally:
        receiver.close()


def test_a_sink_hears_nothing_of_robots_it_does_not_follow(net):
    receiver = Datagrams()
    try:
        net.start(OscSink(OscSinkConfig(subscribe=("nao/events/*",), targets=(receiver.target,)), name="sound"))
        net.sim("nao", rate_hz=20)
        net.sim("pepper", rate_hz=20).stop()
        wait_for(lambda: any(d.startswith(b"/nao/events/connection") for d in receiver.data()), what="nao")
        assert not any(d.startswith(b"/pepper/") for d in receiver.data())
    finally:
        receiver.close()


def test_the_three_machine_example_lets_only_the_control_machine_command(spawn):
    show = str(Path(__file__).parent.parent / "examples" / "three-machines.toml")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = spawn(SONIBUS, "run", show, "--host", "robot-laptop", "--listen", endpoint, "--no-multicast",
                  collect=True)
    wait_for(lambda: any("running pepper" in line for line in robot.lines), timeout=10, what="the robot laptop")

    def send(host: str, *command: str):
        return run_cli("send", "pepper", *command, "--config", show, "--host", host, "--connect", endpoint,
                       "--no-multicast")

    control = send("control-pc", "stop")
    deadline = time.monotonic() + 10
    while control.returncode == 3 and time.monotonic() < deadline:  # until the control machine has joined
        control = send("control-pc", "stop")
    assert control.returncode == 0, control.stderr
    refused = send("sound-pc", "joints/set", "names=HeadYaw", "angles=0.5")
    assert refused.returncode == 4, refused.stderr  # the ACL hides the robot's commands, not the robot
    assert "access control on the robot's machine refuses commands from this machine (user 'sound')" in refused.stderr
    seen = run_cli("nodes", "--config", show, "--host", "sound-pc", "--connect", endpoint, "--no-multicast")
    assert "owns pepper" in seen.stdout, "the sound machine still sees the robot and its data"
    stranger = run_cli("nodes", "--config", show, "--host", "visitor", "--connect", endpoint, "--no-multicast")
    assert stranger.returncode == 2, "a machine without a user of users.txt does not join"
    assert "cannot open the bus" in stranger.stderr and "refuses this machine's login" in stranger.stderr


def test_when_one_robot_leaves_the_other_keeps_playing(net):
    receiver = Datagrams()
    try:
        net.start(OscSink(OscSinkConfig(subscribe=("*/joints/HeadYaw", "*/events/*"), targets=(receiver.target,)),
                          name="sound"))
        pepper = net.sim("pepper", rate_hz=20)
        net.sim("nao", rate_hz=20)
        wait_for(lambda: any(d.startswith(b"/nao/joints/") for d in receiver.data()), what="nao")
        pepper.stop()
        wait_for(lambda: any(d.startswith(b"/pepper/events/connection") and b"lost" in d for d in receiver.data()),
                 what="pepper lost")
        after = len(receiver.data())
        wait_for(lambda: sum(d.startswith(b"/nao/joints/") for d in receiver.data()[after:]) >= 10,
                 what="nao still streaming")
        assert not any(d.startswith(b"/nao/events/connection") and b"lost" in d for d in receiver.data())
    finally:
        receiver.close()
