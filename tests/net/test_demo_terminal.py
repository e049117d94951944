"""Issue 37, items 2 and 3: the second terminal beside `make demo`.

Each test runs in a network namespace of its own (its loopback is its own, so the
demo's fixed port 7448 is free whatever else runs on this machine; scouting by
multicast stays inside). A command without --demo beside a running demo was told "is
sonibus running on another machine … give --connect", and so was one with --demo and no
demo; everything started with --demo listened on every interface (``*:PORT``)."""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path

import pytest

from sonibus.bus.session import sockets

from ..top.test_command import Terminal
from .netns import NsProcess, Topology
from .test_multihost import SINK, show, started, until

pytestmark = pytest.mark.external

BANNER = "sonibus demo:"


def test_a_second_terminal_is_told_whether_this_machines_demo_runs(topology: Topology):
    (me,) = topology.lan("me")  # eth0 on a LAN of its own: what the command scouts, it scouts there
    alone = me.cli("send", "pepper", "say", "hello", "--demo")
    assert alone.returncode == 3, alone.stderr
    assert "no demo is running on this machine" in alone.stderr and "make demo" in alone.stderr, alone.stderr
    assert "another machine" not in alone.stderr, alone.stderr
    waiting = me.cli("echo", "pepper/joints/*", "--demo", "--timeout", "1")  # said at once, while it waits
    assert waiting.returncode == 5, waiting.stderr
    assert "sonibus: hint: no demo is running on this machine" in waiting.stderr, waiting.stderr

    demo = me.sonibus("demo", "--quiet")
    started(topology, demo, "sonibus: running")
    banner = "\n".join(demo.lines)
    assert re.search(r"sonibus send pepper say hello --demo", banner), banner

    missed = me.cli("send", "pepper", "say", "hello")  # no --demo: scouting finds nobody on the LAN
    assert missed.returncode == 3, missed.stderr
    assert "a demo runs on this machine: add --demo" in missed.stderr, missed.stderr
    assert "another machine" not in missed.stderr, missed.stderr

    joined = me.cli("send", "pepper", "say", "hello", "--demo")
    assert joined.returncode == 0, joined.stderr
    assert '"duration"' in joined.stdout, joined.stdout
    assert "private to this machine (no multicast, listening on loopback only)" in banner, banner

    public = me.sonibus("demo", "--quiet", "--robot", "nao", "--port", "9001", "--listen", "tcp/0.0.0.0:7449")
    started(topology, public, "sonibus: running")  # a bus of its own (another port, no multicast)
    banner = "\n".join(public.lines)
    assert "private to this machine" not in banner, banner
    assert "NOT private: listening on tcp/0.0.0.0:7449 — other machines of your network can join" in banner, banner


def listeners(pid: int) -> list[str]:
    """Where process ``pid`` can be reached: its TCP listeners and unconnected UDP sockets."""
    return sorted(sockets(pid).values())


def loopback(where: str) -> bool:
    """``tcp/127.0.0.1:7448`` or ``udp/[::1]:5000``: on loopback."""
    host = where.partition("/")[2].rpartition(":")[0].strip("[]")
    return ipaddress.ip_address(host).is_loopback


def test_everything_started_with_demo_listens_on_loopback_only(topology: Topology, tmp_path: Path):
    (me,) = topology.lan("me")
    demo = me.sonibus("demo", "--quiet")
    started(topology, demo, "sonibus: running")
    sink = show(tmp_path, f"""
        [bus]
        listen = ["tcp/0.0.0.0:7460"]   # for a LAN: --demo leaves it for the demo's bus

        [nodes.sound2]
        subscribe = ["*/joints/*"]
        {SINK.replace("9000", "9002")}
        """)
    second = me.sonibus("demo", "--quiet", "--robot", "nao", "--port", "9001")  # it joins the first's bus
    started(topology, second, "sonibus: running")
    assert any("joining its bus" in line for line in second.lines), second.describe()
    commands: dict[str, NsProcess | Terminal] = {
        "a second demo": second,
        "send": me.sonibus("send", "nobody", "stop", "--demo"),  # (nobody: it looks for a while, then ends)
        "echo": me.sonibus("echo", "pepper/joints/HeadYaw", "--demo"),
        "record": me.sonibus("record", str(tmp_path / "take.mcap"), "--duration", "60", "--demo"),
        "run": me.sonibus("run", sink, "--demo"),
    }
    top = Terminal("--demo", prefix=me.command())
    try:
        commands["top"] = top
        seen: dict[str, list[str]] = {}

        def all_listening() -> bool:
            for name, process in commands.items():
                pid = process.popen.pid if isinstance(process, NsProcess) else process.process.pid
                if name not in seen and listeners(pid):
                    seen[name] = listeners(pid)  # (send's, while it runs: it ends on its own)
            if "send" not in seen and commands["send"].popen.poll() is not None:  # (ended before it was seen,
                commands["send"] = me.sonibus("send", "nobody", "stop", "--demo")  # a busy machine: again)
            return len(seen) == len(commands)

        until(topology, all_listening, 30, "every command listening")
        seen["the demo"] = listeners(demo.popen.pid)
        assert seen["the demo"] == ["tcp/127.0.0.1:7448"], seen["the demo"]
        public = {name: [where for where in found if not loopback(where)] for name, found in seen.items()}
        assert not any(public.values()), f"listening beyond loopback: {public}"
    finally:
        top.close()
