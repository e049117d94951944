"""The disk guard, on a real small file system (tmpfs) inside a real ``sonibus run`` (under a
watchdog: a paused recorder keeps it fed)
with a simulated robot and an OSC sink to oscdump: a warning when space runs
low; below ``min_free_mb`` the file is finished and the recorder pauses (state,
event, ``sonibus nodes``) while the sound goes on and the process stays up; a
disk that fills for real under the writer pauses it too; recording starts again,
into a new file, once space is back."""

from __future__ import annotations

import errno
import os
import shutil
import socket
import time

from sonibus.adapters.recorder import Recording, recover
from sonibus.bus import decode, keys
from sonibus.bus.monitor import Monitor

from ..conftest import SONIBUS, free_port, require_tool, run_cli, wait_for
from .conftest import tmpfs

SHOW = """
[nodes.robot]
adapter = "sim"
robot = "pepper"
rate_hz = 50
body_sound = false

[nodes.sound]
adapter = "osc"
subscribe = ["pepper/joints/HeadYaw"]
targets = ["127.0.0.1:{port}"]

[nodes.logger]
adapter = "recorder"
path = "{disk}/show-{{time}}.mcap"
warn_free_mb = 1.5
min_free_mb = 0.5
"""


def fill(path: str, leave: int) -> None:
    """Write ``path`` until only ``leave`` bytes are free on its disk (0: until it is full)."""
    with open(path, "ab") as f:
        while (room := shutil.disk_usage(os.path.dirname(path)).free - leave) > 0:
            try:
                f.write(os.urandom(min(room, 64 * 1024)))
                f.flush()
            except OSError as exc:
                assert exc.errno == errno.ENOSPC, exc
                return


def logger(monitor: Monitor):
    """The recorder as ``sonibus top`` shows it: (state, why)."""
    node = next((n for n in monitor.snapshot().nodes if n.node == "logger"), None)
    return (node.state, node.error) if node is not None else None


def test_a_full_disk_pauses_the_recorder_and_the_show_goes_on(net, tmp_path, spawn, supervisor):
    oscdump = require_tool("oscdump", "liblo-tools")
    port = free_port(socket.SOCK_DGRAM)
    sound = spawn(oscdump, "-L", str(port), collect=True)
    watch = net.bus("watch")
    events = []
    watch.session.declare_subscriber(keys.NODE_EVENTS, lambda s: events.append(decode(s.payload.to_bytes())))
    with tmpfs("2m") as disk, Monitor(net.bus("top")) as top:
        show = tmp_path / "show.toml"
        show.write_text(SHOW.format(port=port, disk=disk))
        environ = {k: v for k, v in supervisor.environ(watchdog_s=0.6).items() if k != "WATCHDOG_PID"}
        run = spawn(SONIBUS, "run", str(show), *net.cli_args(), collect=True, merge=True,
                    env={**os.environ, **environ})
        said = lambda: "\n".join(run.lines)  # noqa: E731
        first = wait_for(lambda: sorted(f for f in os.listdir(disk) if f.endswith(".mcap")), timeout=20,
                         what="the first file", explain=said)
        wait_for(lambda: f"sonibus: logger: {disk}/{first[0]}" in run.lines, what="where it records", explain=said)
        wait_for(lambda: len(sound.lines) > 20, timeout=10, what="the sound flowing")

        fill(os.path.join(disk, "ballast-1"), leave=1_000_000)  # below warn_free_mb
        wait_for(lambda: any("below warn_free_mb 1.5" in line for line in run.lines), what="the warning",
                 explain=said)
        fill(os.path.join(disk, "ballast-2"), leave=300_000)  # below min_free_mb
        wait_for(lambda: any(e.get("state") == "paused" for e in events), what="the paused event", explain=said)
        paused = next(e for e in events if e.get("state") == "paused")
        assert paused["node"] == "logger" and "the disk is nearly full" in paused["error"], paused
        since = time.monotonic()
        wait_for(lambda: len(supervisor.with_key("WATCHDOG", since)) >= 3, what="watchdog pings while paused",
                 explain=lambda: str(supervisor.messages[-5:]))
        assert not [s for s in supervisor.statuses(since) if s.startswith("unhealthy")], supervisor.statuses(since)
        heard = len(sound.lines)
        _, why = wait_for(lambda: (seen := logger(top)) and seen[0] == "paused" and seen, what="top: paused")
        assert why.startswith("the disk is nearly full: 0."), why
        nodes = run_cli("nodes", *net.cli_args())
        line = next(line for line in nodes.stdout.splitlines() if " logger " in line)
        assert "PAUSED: the disk is nearly full: 0." in line and "below min_free_mb 0.5" in line, nodes.stdout
        with Recording(os.path.join(disk, first[0])) as done:  # finished before the disk filled: whole
            assert done.message_count > 0

        fill(os.path.join(disk, "ballast-3"), leave=0)  # full for real, while it is paused
        wait_for(lambda: len(sound.lines) > heard + 50, timeout=10, what="the sound going on")
        assert run.popen.poll() is None, said()

        events.clear()
        for name in ("ballast-1", "ballast-2", "ballast-3"):
            os.unlink(os.path.join(disk, name))
        wait_for(lambda: any(e.get("state") == "running" for e in events), timeout=10, what="recording again",
                 explain=said)
        wait_for(lambda: logger(top) == ("running", ""), what="top: running, no reason left")
        second = [f for f in sorted(os.listdir(disk)) if f.endswith(".mcap") and f != first[0]]
        assert len(second) == 1, os.listdir(disk)
        wait_for(lambda: os.path.getsize(os.path.join(disk, second[0])) > 10_000, what="a chunk in the new file")

        fill(os.path.join(disk, "ballast-4"), leave=0)  # full for real, under the writer this time
        wait_for(lambda: any(e.get("state") == "paused" for e in events), what="paused again", explain=said)
        heard = len(sound.lines)
        wait_for(lambda: len(sound.lines) > heard + 50, timeout=10, what="the sound going on")
        os.unlink(os.path.join(disk, "ballast-4"))
        code, _, _ = run.stop()
        assert code == 130, said()
        assert not any("Traceback" in line or "FAILED" in line for line in run.lines), said()
        copy = tmp_path / "second.mcap"  # finished, or only closed if the disk filled mid-chunk: recoverable
        shutil.copy(os.path.join(disk, second[0]), copy)
        assert recover(str(copy), str(tmp_path / "second.recovered.mcap"))[0] > 0
