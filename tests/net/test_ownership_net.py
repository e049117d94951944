"""Issue 14, item 1, across machines: two owners of one robot on the two sides of a
network partition, then the network heals. Within the transport lease + 1 s exactly
one owner streams (the one that claimed first), the other says so (a `conflict`
event reaches the sound machine), and no command runs twice — also one sent while
the network heals.

Three namespaces on one LAN, explicit endpoints (a partition that heals is found
again at the reconnect period, not at multicast scouting's, up to 8 s): `hosta` and
`hostb` each run a simulated `pepper`, `sound` an OSC sink (to oscdump) and
`sonibus echo pepper/frame`, connected to both."""

from __future__ import annotations

import json
import time

import pytest

from .netns import NsProcess
from .test_multihost import RATE, SINK, show, started, until

pytestmark = pytest.mark.external

LEASE_S = 1.5            # [bus] lease_ms's default
APART_S = 6.0            # hosta's owner streams this long before hostb's starts: their seqs stay apart


def frames(echo: NsProcess, since: float) -> list[tuple[float, int]]:
    """(t, seq) of each frame echo printed with a ``t`` at or after ``since``: when its owner took
    it, not when this busy process got round to reading echo's output."""
    out = []
    for line in list(echo.lines):
        if line.startswith("pepper/frame "):
            frame = json.loads(line.partition(" ")[2])
            if frame["t"] >= since:
                out.append((frame["t"], frame["seq"]))
    return out


def test_partition_then_heal_leaves_one_owner(topology, tmp_path, figure):
    hosta, hostb, sound = topology.lan("hosta", "hostb", "sound")
    a, b = hosta.endpoint(), hostb.endpoint()
    bus = f"""
        [bus]
        mode = "peer"
        multicast = false
        [bus.hosts.hosta]
        listen = ["{a}"]
        [bus.hosts.hostb]
        listen = ["{b}"]
        connect = ["{a}"]
        [bus.hosts.sound]
        connect = ["{a}", "{b}"]
        """
    owner = f"""
        adapter = "sim"
        robot = "pepper"
        rate_hz = {RATE}
        """
    first = show(tmp_path, f"{bus}\n[nodes.first]\nhost = \"hosta\"\n{owner}\n[nodes.sound]\nhost = \"sound\"\n"
                           f"subscribe = [\"pepper/joints/HeadYaw\", \"pepper/events/*\"]\n{SINK}", "first.toml")
    second = show(tmp_path, f"{bus}\n[nodes.second]\nhost = \"hostb\"\n{owner}", "second.toml")
    dump = sound.oscdump()
    for host in (hosta, sound):
        started(topology, host.sonibus("run", first, "--host", host.name))
    echo = sound.sonibus("echo", "pepper/frame", "--no-multicast", "--connect", a, "--connect", b)
    until(topology, lambda: frames(echo, 0), 10.0, "frames at the echo")
    time.sleep(APART_S)

    topology.cut(hostb)
    b_run = hostb.sonibus("run", second, "--host", "hostb")
    started(topology, b_run)  # alone on its side: it owns pepper there
    assert not any("already owned" in line for line in b_run.errors)
    time.sleep(1.0)

    healed = topology.restore(hostb)
    seq_at_heal = frames(echo, 0)[-1][1]
    during = sound.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=0.3", "speed=1.0",
                       "--no-multicast", "--connect", a, "--connect", b)
    settled = healed + LEASE_S + 1.0
    until(topology, lambda: time.time() > settled + 1.5, 10.0, "a window after the heal")

    late = [(read, seq) for read, seq in frames(echo, healed) if seq < seq_at_heal]  # hostb's counter is behind
    last_b = max((read for read, _ in late), default=healed)
    figure("hostb's owner streamed after the heal for", last_b - healed, "s")
    assert last_b <= settled, f"hostb's owner still streamed {last_b - healed:.2f} s after the heal"
    after = [seq for read, seq in frames(echo, settled)]
    assert after and after == sorted(after) and len(set(after)) == len(after), "one owner's frames, in order"
    assert min(after) > seq_at_heal, "hosta's owner (the first claim) keeps streaming"

    conflict = until(topology, lambda: dump.messages("/pepper/events/conflict"), 5.0, "a conflict event at sound")
    figure("conflict event at sound after the heal", conflict[0].read - healed, "s")
    assert '"standby"' in conflict[0].args
    stood_by = [line for line in b_run.errors if "which claimed it first: this node stands by" in line]
    assert stood_by and "node 'first' on host 'hosta'" in stood_by[0], b_run.describe()

    assert during.returncode == 0, during.stderr
    asked = time.time()
    after_heal = sound.cli("send", "pepper", "joints/set", "names=HeadYaw", "angles=-0.3", "speed=1.0",
                           "--no-multicast", "--connect", a, "--connect", b)
    assert after_heal.returncode == 0, after_heal.stderr
    until(topology, lambda: [m for m in dump.messages("/pepper/events/command") if m.read >= asked], 5.0,
          "the command event")
    time.sleep(0.5)
    executed = [m for m in dump.messages("/pepper/events/command") if '"joints/set" 1' in m.args]
    figure("commands executed twice (2 sent, one during the heal)", max(0, len(executed) - 2))
    assert len(executed) == 2, f"2 commands sent, {len(executed)} executions: {[m.args for m in executed]}"
