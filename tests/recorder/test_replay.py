"""Replay: a recording back onto the bus, into the same sinks, with its timing —
what oscdump receives equals what it received live."""

from __future__ import annotations

import socket
import statistics
import time

import numpy as np
import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.bus import CommandError, OwnershipError, decode, robot_info, send_command

from ..conftest import free_port, run_cli, wait_for
from ..osc.pd import oscdump_lines, start_oscdump
from .conftest import HEY, record_sim, settle


def oscdump_time(line: str) -> float:
    sec, _, frac = line.split(" ", 1)[0].partition(".")
    return int(sec, 16) + int(frac, 16) / 2**32


def test_replay_into_osc_equals_live_and_keeps_its_timing(net, tmp_path, spawn):
    port = free_port(socket.SOCK_DGRAM)
    dump = start_oscdump(spawn, port)
    net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=(f"127.0.0.1:{port}",)), name="sound"))
    path = tmp_path / "live.mcap"
    _, reference = record_sim(net, path, frames=150)
    sent = sum(1 for key, _ in reference if "/joints/" in key)
    settle(lambda: len(oscdump_lines(dump)))
    live = oscdump_lines(dump)
    assert len(live) == sent, "the live run lost samples: the comparison needs all of them"

    result = run_cli("replay", str(path), *net.cli_args(), timeout=30)
    assert result.returncode == 0, result.stderr
    settle(lambda: len(oscdump_lines(dump)))
    replayed = oscdump_lines(dump)[len(live):]
    assert [line.split(" ", 1)[1] for line in replayed] == [line.split(" ", 1)[1] for line in live]

    with Recording(str(path)) as recording:
        logged = [m.log_ns / 1e9 for m in recording.messages([k for k in recording.keys if "/joints/" in k])]
    arrived = [oscdump_time(line) for line in replayed]
    error = np.array(arrived) - arrived[0] - (np.array(logged) - logged[0])
    error -= np.median(error)
    p99_ms = float(np.percentile(np.abs(error), 99)) * 1e3
    print(f"replay timing error at oscdump: p50 {np.median(np.abs(error)) * 1e3:.3f} ms, p99 {p99_ms:.3f} ms")
    assert p99_ms <= 2.0, f"timing error p99 {p99_ms:.2f} ms"


def test_a_renamed_replay_runs_beside_the_live_robot_and_takes_no_commands(net, recorded):
    path, _ = recorded
    net.sim("pepper", rate_hz=20)
    replay = net.start(Replay(ReplayConfig(path=str(path), rename={"pepper": "take1"}), name="take"))
    bus = net.bus("watch")
    _, joints = bus.subscribe("take1/joints/HeadYaw")
    _, events = bus.subscribe("take1/events/*")
    info = wait_for(lambda: robot_info(bus, "take1", timeout=0.5), what="take1/info")
    assert info["robot"] == "take1" and info["replay"]["robot"] == "pepper" and info["owner"]["node"] == "take"
    assert len(info["joints"]) == 17
    assert robot_info(bus, "pepper")["owner"]["node"] == "sim-pepper"
    sample = decode(wait_for(lambda: joints.get(timeout=0.1), what="a replayed sample")[1])
    assert abs(sample["t"] - time.time()) < 0.5, "t is moved to now, so sinks do not drop it as stale"
    with pytest.raises(CommandError) as refused:
        send_command(bus, "take1", "joints/set", {"names": ["HeadYaw"], "angles": [0.1]})
    assert refused.value.code == "failed" and "takes no commands" in str(refused.value)
    assert send_command(bus, "take1", "stop", {}) == {}
    behavior = []

    def hey_started():
        while (item := events.get(timeout=0)) is not None:
            behavior.append(decode(item[1]))
        return any(e.get("name") == HEY and e.get("state") == "started" for e in behavior)

    wait_for(hey_started, what="the recorded behavior event")
    wait_for(replay.finished.is_set, timeout=10, what="the end of the replay")


def test_loop_window_and_speed(net, recorded):
    path, _ = recorded
    bus = net.bus("watch")
    _, queue = bus.subscribe("pepper/joints/HeadYaw", maxlen=100_000)
    replay = net.start(Replay(ReplayConfig(path=str(path), loop=True, speed=4.0, start=0.5, end=1.5), name="take"))
    wait_for(lambda: replay.loops >= 3, timeout=10, what="three passes")
    replay.stop()
    got = []
    while (item := queue.get(timeout=0)) is not None:
        got.append((time.monotonic(), decode(item[1])))
    seqs = [d["seq"] for _, d in got]
    assert seqs == sorted(set(seqs)), "seq keeps counting up across passes"
    with Recording(str(path)) as recording:
        window = [m.data["v"] for m in recording.messages(["pepper/joints/HeadYaw"], 0.5, 1.5)]
    assert 40 <= len(window) <= 52  # one second of 50 frames/s
    values = [d["v"] for _, d in got]
    assert values[: 2 * len(window)] == window * 2, "each pass plays the window from its start"
    steps = np.diff([d["t"] for _, d in got[: len(window)]])
    assert statistics.median(steps) == pytest.approx(0.02 / 4, rel=0.05), "t advances at 4x"


def test_a_robot_already_on_the_bus_is_not_replayed_over(net, recorded):
    path, _ = recorded
    net.sim("pepper", rate_hz=20)
    with pytest.raises(OwnershipError, match=r"already owned by node 'sim-pepper'.*--as pepper="):
        net.start(Replay(ReplayConfig(path=str(path)), name="take"))
    result = run_cli("replay", str(path), *net.cli_args())
    assert result.returncode == 1
    assert "--as pepper=" in result.stderr and len(result.stderr.splitlines()) == 1
