"""The model behind ``sonibus top`` (bus/monitor.py) on a real bus: robots with their
owner, model, rate, latency, gaps and joint limits; nodes with their stats; events;
bad messages counted, never fatal; a robot or node that leaves stays, as gone."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import pytest

from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import Adapter, CommandError, encode, framing, keys, load_model, send_command
from sonibus.bus.monitor import Monitor, Snapshot

from ..conftest import wait_for
from ..wakes import named, wakes


def robot(snapshot: Snapshot, name: str):
    return next((r for r in snapshot.robots if r.name == name), None)


def node(snapshot: Snapshot, name: str):
    return next((n for n in snapshot.nodes if n.node == name), None)


def test_a_robot_shows_its_owner_model_rate_latency_and_joints_within_its_limits(net):
    sim = net.sim("pepper", rate_hz=50)
    with Monitor(net.bus("top")) as monitor:
        seen = wait_for(lambda: (r := robot(monitor.snapshot(), "pepper")) and r.model and r.rate_hz > 10 and r,
                        what="pepper with its info and frames")
    assert seen.owner == f"{sim.bus.host}/sim-pepper" and seen.model == "pepper" and not seen.gone
    assert seen.latency_ms is not None and seen.latency_ms >= 0
    model = load_model("pepper")
    assert [j.name for j in seen.joints] == list(model.joint_names)
    for joint in seen.joints:
        spec = model.joint(joint.name)
        assert (joint.min, joint.max, joint.unit) == (spec.min, spec.max, spec.unit)
        assert 0.0 <= joint.fraction <= 1.0 and joint.history


def test_frames_missing_by_seq_are_counted_as_gaps_and_a_restart_is_none(net):
    script = net.bus("script")
    with Monitor(net.bus("top")) as monitor:
        def put(seq: int) -> None:
            script.put(keys.frame("bot"), framing.frame(time.time(), seq, ["HeadYaw"], [0.1 * seq]))

        put(1)  # (the subscription may not reach the script yet: until the first frame is seen)
        wait_for(lambda: robot(monitor.snapshot(), "bot") or put(1), what="the first frame of bot")
        for seq in (2, 5, 6, 1, 2, 9):  # 3 and 4 missing; then it starts over (no gap); 3..8 missing
            put(seq)
        seen = wait_for(lambda: (r := robot(monitor.snapshot(), "bot")) and r.joints[0].value == 0.9 and r,
                        what="the last frame")
    assert seen.gaps == 2 + 6
    assert seen.owner == "" and not seen.gone  # frames with nobody claiming the robot: shown, owner unknown


def test_bad_stats_and_events_are_counted_and_named_and_the_monitor_goes_on(net):
    script = net.bus("script")
    with Monitor(net.bus("top")) as monitor:
        stats = script.session.declare_publisher(keys.node_stats("rogue", "node"))
        wait_for(lambda: stats.matching_status.matching, what="the monitor's stats subscription")
        stats.put(b"\xc1 not msgpack")
        script.put(keys.node_stats("rogue", "node"), {"t": time.time(), "host": "rogue"})  # fields missing
        script.put(keys.event("pepper", "behavior"), {"t": time.time(), "kind": "behavior"})  # name, state missing
        wait_for(lambda: monitor.snapshot().counters["bad"] >= 3, what="three bad messages counted")
        assert "sonibus/stats/rogue/node" in monitor.snapshot().problem or "pepper/events/behavior" in \
            monitor.snapshot().problem
        script.put(keys.event("pepper", "speech"), {"t": time.time(), "kind": "speech", "text": "hi", "state": "done"})
        event = wait_for(lambda: monitor.snapshot().events, what="a good event after the bad ones")[-1]
    assert (event.source, event.kind, event.text, event.alarm) == ("pepper", "speech", "done 'hi'", False)
    assert len(monitor.snapshot().events) == 1  # the bad one is not listed
    assert node(monitor.snapshot(), "node") is None  # refused stats make no node


def test_a_robot_and_its_node_leaving_are_shown_as_gone_and_stay_listed(net):
    sim = net.sim("nao", rate_hz=20)
    with Monitor(net.bus("top")) as monitor:
        wait_for(lambda: (r := robot(monitor.snapshot(), "nao")) and r.frames
                 and (n := node(monitor.snapshot(), "sim-nao")) and n.adapter == "sim", what="nao and its node")
        assert node(monitor.snapshot(), "sim-nao").state == "running"
        sim.stop()
        wait_for(lambda: robot(monitor.snapshot(), "nao").gone, what="nao shown as gone")
        wait_for(lambda: node(monitor.snapshot(), "sim-nao").gone, what="its node shown as gone")
        snapshot = monitor.snapshot()
    assert robot(snapshot, "nao").owner == "" and robot(snapshot, "nao").joints  # its last values stay
    assert node(snapshot, "sim-nao").adapter == "sim"
    said = {(e.source, e.kind, e.text, e.alarm) for e in snapshot.events}
    assert ("nao", "connection", "left the bus: its owner's claim went", True) in said, said
    assert (f"{sim.bus.host}/sim-nao", "node", "gone: its token vanished", True) in said, said


def test_a_robot_back_on_the_bus_is_no_longer_gone(net):
    first = net.sim("nao", rate_hz=20)
    with Monitor(net.bus("top")) as monitor:
        wait_for(lambda: (r := robot(monitor.snapshot(), "nao")) and r.model, what="nao with its info")
        first.stop()
        wait_for(lambda: robot(monitor.snapshot(), "nao").gone, what="nao gone")
        again = net.start(SimRobot(SimConfig(robot="nao", rate_hz=20), name="nao-again"))
        back = wait_for(lambda: (r := robot(monitor.snapshot(), "nao")) and not r.gone and r.model and r,
                        what="nao back, with its info")
        events = monitor.snapshot().events
    assert back.owner == f"{again.bus.host}/nao-again"
    assert f"on the bus again, owned by node 'nao-again' on host '{again.bus.host}'" in [e.text for e in events]
    assert not events[-1].alarm


def test_a_second_claim_of_a_robot_is_shown_standing_by(net):
    """A rival claim, later than the owner's: the owner keeps the robot and says so."""
    sim = net.sim("pepper", rate_hz=20)
    rival = net.bus("rival")
    with Monitor(net.bus("top")) as monitor:
        wait_for(lambda: (r := robot(monitor.snapshot(), "pepper")) and r.owner, what="pepper's owner")
        claim = rival.token(f"{keys.ROBOTS}/pepper/{time.time_ns() // 1_000_000 + 1000}/stage/understudy")
        seen = wait_for(lambda: (r := robot(monitor.snapshot(), "pepper")) and r.standby and r,
                        what="the second claim")
        conflict = wait_for(lambda: [e for e in monitor.snapshot().events if e.kind == "conflict"],
                            what="the owner's conflict event")[0]
        claim.undeclare()
    assert seen.owner == f"{sim.bus.host}/sim-pepper" and seen.standby == ("stage/understudy",)
    assert conflict.alarm and conflict.text == f"standby, owner sim-pepper on {sim.bus.host}"


class Lossy(Adapter):
    """A node that drops something every few milliseconds, and receives."""

    @dataclass(frozen=True)
    class Config:
        pass

    def _start(self) -> None:
        self.spawn(self._lose, "lose")

    def _lose(self) -> None:
        while not self.stopping.wait(0.01):
            self.count("dropped")
            self.count("received", 10)


class Failing(Adapter):
    """A node whose worker dies once told to."""

    @dataclass(frozen=True)
    class Config:
        pass

    def _start(self) -> None:
        self.die = threading.Event()
        self.spawn(self._work, "work")

    def _work(self) -> None:
        while not self.stopping.wait(0.01):
            if self.die.is_set():
                raise RuntimeError("the lamp broke")


def test_node_stats_show_rates_losses_that_moved_and_a_failure(net):
    with Monitor(net.bus("top")) as monitor:
        lossy = net.start(Lossy(name="lossy"))
        failing = net.start(Failing(name="failing"))
        seen = wait_for(lambda: (n := node(monitor.snapshot(), "lossy")) and n.counters["dropped"] and n,
                        what="lossy's stats")
        assert seen.host == lossy.bus.host and seen.adapter == "Lossy" and seen.state == "running"  # (its class name)
        assert "dropped" in seen.moved and seen.rx_per_s > 0 and seen.uptime_s is not None
        assert node(monitor.snapshot(), "failing").moved == ()
        failing.die.set()
        failed = wait_for(lambda: (n := node(monitor.snapshot(), "failing")) and n.state == "failed" and n,
                          what="the failed node")
        event = wait_for(lambda: [e for e in monitor.snapshot().events if e.kind == "node"], what="its event")[0]
        failing.stop()
        wait_for(lambda: node(monitor.snapshot(), "failing").gone, what="the failed node gone")
        net.start(Lossy(name="failing"))  # started again under the same name: a new node
        # (the monitor asks a node as soon as its token comes, now: it may say "starting" first)
        again = wait_for(lambda: (n := node(monitor.snapshot(), "failing")) and n.adapter == "Lossy"
                         and n.state == "running" and n, what="the node started again, running")
    assert again.error == ""  # (the failure of the node that had its name is not carried over)
    assert "the lamp broke" in failed.error
    assert event.source == f"{failing.bus.host}/failing" and event.alarm and "the lamp broke" in event.text


def test_a_note_of_the_viewer_is_listed_with_the_events(net):
    with Monitor(net.bus("top")) as monitor:
        monitor.note("pepper", "stop", "ok: stopped")
        (event,) = monitor.snapshot().events
    assert (event.source, event.kind, event.text) == ("pepper", "stop", "ok: stopped")


def test_robots_beyond_the_most_it_keeps_are_counted_not_kept(net):
    script = net.bus("script")
    with Monitor(net.bus("top"), most=2) as monitor:
        def put(name: str) -> None:
            script.put(keys.frame(name), framing.frame(time.time(), 1, ["HeadYaw"], [0.5]))

        wait_for(lambda: robot(monitor.snapshot(), "a") or put("a"), what="the first robot")
        for name in ("b", "c", "d"):
            put(name)
        wait_for(lambda: monitor.snapshot().counters["bad"] >= 2, what="the robots over the limit counted")
        snapshot = monitor.snapshot()
    assert [r.name for r in snapshot.robots] == ["a", "b"]
    assert snapshot.problem == "robot 'd' not shown: already 2 listed"


def test_the_same_event_in_a_row_is_counted_on_one_line_and_a_refusal_is_an_alarm(net):
    net.sim("pepper", rate_hz=20)
    sender = net.bus("sliders")
    with Monitor(net.bus("top")) as monitor:
        wait_for(lambda: robot(monitor.snapshot(), "pepper"), what="pepper")
        for angle in (0.1, 0.2, 0.3, 0.4, 0.5):  # a slider's moves
            send_command(sender, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [angle]})
        with pytest.raises(CommandError) as refused:
            send_command(sender, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [9.0]})
        events = wait_for(lambda: len(e := monitor.snapshot().events) == 2 and e, what="two lines",
                          explain=lambda: str(monitor.snapshot()))
    assert refused.value.code == "out_of_range"
    assert [(e.text, e.repeated, e.alarm) for e in events] == [
        ("joints/set ok", 5, False), (f"joints/set refused: {refused.value.message}", 1, True)]


def test_a_node_description_of_the_wrong_types_shows_what_is_usable(net):
    rogue = net.bus("rogue")
    key = keys.node_token("stage", "liar")
    liar = {"adapter": 5, "state": "starting", "since": "yesterday", "failure": ["no"]}
    served = rogue.serve(key, lambda query: query.reply(key, encode(liar), encoding="application/msgpack"))
    token = rogue.token(key)
    with Monitor(net.bus("top")) as monitor:
        shown = wait_for(lambda: (n := node(monitor.snapshot(), "liar")) and n.state == "starting" and n,
                         what="the node, from its token and description")
        assert (shown.adapter, shown.uptime_s, shown.error) == ("?", None, "")
    token.undeclare()
    served.undeclare()


def test_with_nothing_on_the_bus_its_worker_sleeps_and_a_node_that_comes_is_asked(net):
    """The worker sleeps until a message or a token comes (before: a 0.25 s timeout, 4 wake-ups a
    second; issue 35); a node's token wakes it to ask what the node is."""
    with Monitor(net.bus("top")) as monitor:
        [worker] = named("monitor")
        counted = wakes([worker], 2.0)
        assert counted["monitor"] <= 1, counted  # (a count: the GIL's waits count too; before: 8)
        net.sim("pepper", rate_hz=50)
        wait_for(lambda: (n := node(monitor.snapshot(), "sim-pepper")) and n.adapter == "sim", 5,
                 "the sim node, asked what it is")
