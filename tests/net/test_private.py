"""Issue 26, item 9: a shared network is not shared by default. Two people on one LAN:
their demos keep to their machines (nothing leaves loopback), and two installations with
a namespace each neither hear nor stop each other; a robot taken by another
installation is refused with an error that points to the namespace."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest

from .netns import Host, Topology
from .test_multihost import SIM, SINK, show, started, streaming, until

pytestmark = pytest.mark.external

STOP_ALL = str(Path(__file__).with_name("stop_all.py"))


def stop_all(host: Host, *bus: str) -> dict:
    """What ``client.stop_all`` (the page's STOP, top's ``s``) got, run on ``host``."""
    done = host.call(sys.executable, STOP_ALL, *bus, timeout=30)
    assert done.returncode == 0, f"stop_all on {host.name}: {done.stdout} {done.stderr}"
    return json.loads(done.stdout.strip().splitlines()[-1])


def installation(tmp_path: Path, name: str, host: str, namespace: str) -> str:
    """A robot ``pepper`` and a sound machine's OSC sink (joints and events), on ``host``."""
    return show(tmp_path, f"""
        [bus]
        multicast = true
        namespace = "{namespace}"

        [nodes.robot]
        host = "{host}"
        robot = "pepper"
        {SIM}
        [nodes.sound]
        host = "{host}"
        subscribe = ["*/joints/*", "*/events/*"]
        {SINK}
        """, f"{name}.toml")


def test_two_installations_with_a_namespace_each_neither_hear_nor_stop_each_other(topology: Topology, tmp_path):
    alice, bob = topology.lan("alice", "bob")
    alice_toml = installation(tmp_path, "alice", "alice", "alice")
    copied = installation(tmp_path, "copied", "bob", "alice")  # bob runs a copy of alice's file
    bob_toml = installation(tmp_path, "bob", "bob", "bob")
    alice_dump, bob_dump = alice.oscdump(), bob.oscdump()
    started(topology, alice.sonibus("run", alice_toml, "--host", "alice"))
    streaming(topology, alice_dump)

    taken = bob.sonibus("run", copied, "--host", "bob")
    until(topology, lambda: not taken.running, 20, "the copy to be refused")
    refusal = [line for line in taken.errors if "already owned" in line]
    assert refusal, taken.describe()
    assert "node 'robot' on host 'alice'" in refusal[0] and "namespace" in refusal[0], refusal[0]

    started(topology, bob.sonibus("run", bob_toml, "--host", "bob"))  # its own namespace: its own pepper
    streaming(topology, bob_dump)

    before = time.time()
    stopped = stop_all(alice, "--config", alice_toml, "--host", "alice")
    assert stopped["answered"] == {"pepper": "ok"} and stopped["silent"] == [], stopped
    until(topology, lambda: [m for m in alice_dump.since(before, "/pepper/events/command") if "stop" in m.args],
          10, "alice's stop heard by alice's sink")
    stopped = stop_all(bob, "--config", bob_toml, "--host", "bob")
    assert stopped["answered"] == {"pepper": "ok"}, stopped
    until(topology, lambda: [m for m in bob_dump.since(before, "/pepper/events/command") if "stop" in m.args],
          10, "bob's stop heard by bob's sink")
    stops = [m for m in bob_dump.since(before, "/pepper/events/command") if "stop" in m.args]
    assert len(stops) == 1, f"bob's robot was stopped {len(stops)} times: alice's STOP reached it"
    stops = [m for m in alice_dump.since(before, "/pepper/events/command") if "stop" in m.args]
    assert len(stops) == 1, f"alice's robot was stopped {len(stops)} times: bob's STOP reached it"

    listed = alice.cli("nodes", "--config", alice_toml, "--host", "alice")
    assert listed.returncode == 0 and "bob" not in listed.stdout, listed.stdout


def test_two_demos_on_one_network_keep_to_their_machines(topology: Topology):
    """Two people's `make demo` on one network: the second's OSC target got the first's robot,
    and the page's STOP and top's `s` stopped the colleague's robot."""
    alice, bob = topology.lan("alice", "bob")
    for host in (alice, bob):
        host.without_ipv6()
    dumps = {alice: alice.oscdump(), bob: bob.oscdump()}
    sent = {host: host.sent_packets() for host in (alice, bob)}
    demos = [alice.sonibus("demo", "--quiet"), bob.sonibus("demo", "--quiet", "--robot", "nao")]
    for demo in demos:
        started(topology, demo, "sonibus demo:")
    streaming(topology, dumps[alice], "pepper")
    streaming(topology, dumps[bob], "nao")
    time.sleep(1.0)  # both demos stream side by side for a while
    assert not dumps[alice].messages("/nao/"), "alice's OSC target got bob's robot"
    assert not dumps[bob].messages("/pepper/"), "bob's OSC target got alice's robot"
    for host in (alice, bob):
        assert host.sent_packets() == sent[host], f"{host.name}'s demo sent packets out of eth0"
    stopped = stop_all(alice, "--demo")  # top's `s` and the page's STOP, on alice's machine
    assert stopped["answered"] == {"pepper": "ok"}, stopped
