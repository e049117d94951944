"""A robot that stops answering without closing (frozen, or a link that vanished):
Ctrl-C and SIGTERM still end the adapter within 3 s, and it streams again once
the robot answers — no NAOqi call waits without a bound (issue 14)."""

from __future__ import annotations

import signal
import time

import pytest

from sonibus.bus import send_command

from ..conftest import SONIBUS, wait_for
from ..test_commands import Joints
from .conftest import attach, toml_node
from .relay import Relay

EXIT_BOUND_S = 3.0  # what issue 14 asks of Ctrl-C with a frozen robot


def frames_stopped(joints: Joints, quiet_s: float = 0.3) -> bool:
    """No new frame for ``quiet_s``: the adapter is waiting on the robot."""
    joints.poll()
    newest = max(joints.by_seq, default=-1)
    time.sleep(quiet_s)
    joints.poll()
    return max(joints.by_seq, default=-1) == newest


@pytest.mark.parametrize(("when", "sig"), [("reading", signal.SIGINT), ("reconnecting", signal.SIGINT),
                                           ("reconnecting", signal.SIGTERM)])
def test_a_signal_ends_the_adapter_within_3_s_while_the_robot_is_frozen(net, spawn, tmp_path, fake_process,
                                                                         when, sig, figure):
    fake = fake_process()
    show = tmp_path / "robot.toml"
    show.write_text(toml_node("pepper", adapter="naoqi", url=fake.url, rate_hz=50, pause_awareness=True,
                              connect_timeout_s=5.0 if when == "reading" else 0.5, retry_max_s=0.5))
    robot = spawn(SONIBUS, "run", str(show), *net.cli_args(), collect=True, merge=True)
    joints = Joints(net.bus("watch"), "pepper")
    wait_for(joints.complete, timeout=20.0, what="frames from the adapter process",
             explain=lambda: "\n".join(robot.lines))
    fake.freeze()
    wait_for(lambda: frames_stopped(joints), what="the frames to stop")
    if when == "reconnecting":  # the read timed out: the adapter drops the link and dials the frozen robot
        wait_for(lambda: any("lost robot" in line for line in robot.lines), what="the adapter to see the loss",
                 explain=lambda: "\n".join(robot.lines))
    started = time.monotonic()
    robot.popen.send_signal(sig)
    try:
        robot.popen.wait(timeout=15.0)
    finally:
        elapsed = time.monotonic() - started
        figure(f"frozen robot, {when}: exit after {signal.Signals(sig).name}", elapsed, "s")
    assert elapsed <= EXIT_BOUND_S, f"exited after {elapsed:.1f} s:\n" + "\n".join(robot.lines)
    assert robot.popen.returncode == 130
    assert not [line for line in robot.lines if "Traceback" in line], robot.lines


def test_frozen_then_resumed_streams_again(net, fake_process, figure):
    fake = fake_process()
    r = attach(net, fake.url, connect_timeout_s=0.5, retry_max_s=0.5)
    r.events.wait("connection", state="connected")
    fake.freeze()
    r.events.wait("connection", timeout=5.0, state="lost")
    wait_for(lambda: frames_stopped(r.joints, 1.0), what="reconnect attempts on the frozen robot")
    outage = r.joints.last()[0]
    resumed = time.time()
    fake.resume()
    wait_for(lambda: r.events.find("connection", state="connected")[1:], timeout=10.0, what="connected again")
    assert r.joints.next(5)[0][0] > outage
    first = r.joints.complete(outage)[0][0]
    figure("frozen then resumed: first frame after the resume", r.joints.t[first] - resumed, "s")
    assert send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.3]}) == {}


def test_a_link_that_vanishes_without_closing_is_replaced(net, fakes):
    """Wi-Fi drop: the old connection goes silent for good (no FIN, no RST); the robot is reachable
    again on a new one. Nothing the adapter does on the dead link may hold up the new one."""
    robot = fakes()
    relay = Relay(int(robot.url.rsplit(":", 1)[1])).start()
    try:
        r = attach(net, relay.url(), connect_timeout_s=0.5, retry_max_s=0.5, fake=robot)
        r.events.wait("connection", state="connected")
        relay.cut()
        r.events.wait("connection", timeout=5.0, state="lost")
        outage = r.joints.last()[0]
        wait_for(lambda: r.events.find("connection", state="connected")[1:], timeout=5.0,
                 what="connected again on a new link")
        assert r.joints.next(5)[0][0] > outage
        send_command(r.bus, "pepper", "behavior/run", {"name": "animations/Stand/Gestures/Yes_1"})
        r.events.wait("behavior", state="started")  # signals connected on the new link
        started = time.monotonic()
        relay.cut()  # and once more, now stopping while the link is dead
        r.adapter.stop()
        assert time.monotonic() - started <= EXIT_BOUND_S
    finally:
        relay.stop()


def test_stop_is_bounded_while_every_call_stalls(rig):
    """naoqi-sim's frozen mode: the socket answers, NAOqi's methods never do."""
    r = rig(pause_awareness=True, connect_timeout_s=5.0)
    r.fake.freeze()
    wait_for(lambda: frames_stopped(r.joints), what="the frames to stop")
    started = time.monotonic()
    r.adapter.stop()
    assert time.monotonic() - started <= EXIT_BOUND_S
    assert r.adapter.state == "stopped"

