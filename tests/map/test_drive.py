"""Maps that drive a robot, on a real bus with a simulated Pepper owner: a closed show
sends none (and an open one again), the owner's refusal of an angle past a joint's
limits is said and moves nothing, a threshold sends a posture, and ``resume`` takes
only what it knows."""

from __future__ import annotations

import logging
import time

from sonibus.bus import client, codec, keys
from sonibus.bus.commands import ok_reply
from sonibus.bus.errors import CommandError

from ..conftest import wait_for
from .conftest import map_node
from .test_node import Listen

TEXT = '''[nodes.moves]
adapter = "map"
[nodes.moves.maps.look]
source = "lab/derived/knob/a"
from = [0, 1]
to = [-0.5, 0.5]
target = { robot = "pepper", command = "joints/set", joint = "HeadYaw", hz = 50 }
[nodes.moves.maps.bow]
source = "lab/derived/knob/b"
from = [0, 1]
threshold = [0.8, 0.2]
target = { robot = "pepper", command = "posture", name = "Crouch", speed = 0.5 }
[nodes.moves.maps.wide]
source = "lab/derived/knob/c"
from = [0, 1]
to = [0, 3]
target = { robot = "pepper", command = "joints/set", joint = "HeadYaw" }
'''


class Rig:
    def __init__(self, net) -> None:
        self.robot = net.sim("pepper", speaker=False, body_sound=False)
        self.node = map_node(net, TEXT, node="moves")
        self.bus = net.bus("lab")
        self.events = Listen(self.bus, "pepper/events/*")
        self.seq = 0

    def knob(self, name: str, value: float) -> None:
        self.seq += 1
        self.bus.put(keys.derived("lab", "knob", name), {"t": time.time(), "seq": self.seq, "v": value})

    def commands(self, verb: str) -> list[dict]:
        return [m for m in self.events.on("pepper/events/command") if m.get("verb") == verb]

    def program(self, verb: str, args: dict) -> object:
        got: list = []
        client.ask_program(self.bus, "moves", verb, args, got.append, 2.0)
        return wait_for(lambda: got, what=f"the answer to {verb}")[0]


def test_a_closed_show_sends_none_and_an_open_one_again(net):
    rig = Rig(net)
    wait_for(lambda: rig.bus.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    rig.knob("a", 1.0)
    wait_for(lambda: rig.commands("joints/set"), what="the first joints/set")
    assert rig.commands("joints/set")[0]["args"]["angles"] == [0.5]
    rig.bus.put(keys.event("pepper", "show"), {"t": time.time(), "kind": "show", "state": "closed"})
    wait_for(lambda: "pepper" in rig.node._drive.closed, what="the show's closing heard")
    assert rig.node.metrics()["closed_robots"] == {"pepper": 1}
    for value in (0.0, 0.25, 0.75):
        rig.knob("a", value)
    wait_for(lambda: rig.node.stats["closed"] == 3, what="three values held back")
    assert len(rig.commands("joints/set")) == 1
    rig.bus.put(keys.event("pepper", "show"), {"t": time.time(), "kind": "show", "state": "open"})
    wait_for(lambda: "pepper" not in rig.node._drive.closed, what="the show's opening heard")
    rig.knob("a", 0.0)
    wait_for(lambda: len(rig.commands("joints/set")) == 2, what="a joints/set once open")
    assert rig.commands("joints/set")[1]["args"]["angles"] == [-0.5]


def test_an_angle_past_the_limits_is_refused_by_the_owner_and_said(net, caplog):
    rig = Rig(net)
    wait_for(lambda: rig.bus.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    # said once the robot's info comes, before any value: the map's to goes past the joint's limits
    wait_for(lambda: "map 'wide': to = [0, 3] goes past HeadYaw's limits [-2.08567, 2.08567]: pepper refuses "
                     "the angles past them" in caplog.text, what="the warning about to")
    assert "map 'look'" not in caplog.text
    with caplog.at_level(logging.WARNING):
        rig.knob("c", 1.0)  # 3 rad: HeadYaw's limits are ±2.0857
        wait_for(lambda: "map 'wide': pepper refused joints/set names = ['HeadYaw'], angles = [3.0], speed = 0.3: "
                         "out_of_range" in caplog.text, what="the refusal said")
    # (the owner's command event comes on a key of its own: maybe after the map node's refusal)
    refused = wait_for(lambda: rig.commands("joints/set"), what="the owner's command event")[0]
    assert refused["ok"] is False and "outside its limits" in refused["error"]
    assert rig.node.stats["commands_refused"] == 1


def test_a_threshold_sends_a_posture_once_each_time_it_turns_on(net):
    rig = Rig(net)
    wait_for(lambda: rig.bus.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    for value in (0.1, 0.9, 0.95, 0.85):  # on once, hovering above: one posture
        rig.knob("b", value)
    wait_for(lambda: rig.commands("posture"), what="the posture")
    wait_for(lambda: rig.node.stats["received"] >= 4, what="every value taken")
    assert [c["args"] for c in rig.commands("posture")] == [{"name": "Crouch", "speed": 0.5}]


def test_resume_takes_only_the_robots_the_node_drives(net):
    rig = Rig(net)
    wait_for(lambda: rig.bus.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    answer = rig.program("resume", {"robot": "nao"})
    assert isinstance(answer, CommandError) and answer.code == "bad_request"
    assert "no map of node 'moves' drives 'nao' — its robots: pepper" in answer.message
    unknown = rig.program("dance", {})
    assert isinstance(unknown, CommandError) and unknown.code == "unknown_verb"
    assert rig.program("resume", {}) == {"resumed": [], "robots": ["pepper"], "halted": {}, "closed": [],
                                         "maps": {"look": "pepper joints/set HeadYaw", "bow": "pepper posture Crouch",
                                                  "wide": "pepper joints/set HeadYaw"}}


def test_a_command_on_its_way_when_the_robot_is_stopped_is_followed_by_a_stop_of_the_nodes_own(net):
    # an owner that holds joints/set unanswered (a busy robot) and says a stop as a real one does: the map's
    # joints/set may be carried out after the operator's stop, so the node stops the robot once more
    owner = net.bus("owner")
    held, stops = [], []

    def serve(query) -> None:
        verb = keys.command_verb(str(query.key_expr))
        if verb == "stop":
            stops.append(time.time())
            query.reply(keys.command("pepper", "stop"), codec.encode(ok_reply("stop", {"held": True})))
        else:
            held.append(query)  # (answered below, after the stop)

    queryable = owner.session.declare_queryable("pepper/cmd/**", serve)
    node = map_node(net, TEXT, node="moves")
    lab = net.bus("lab")
    wait_for(lambda: lab.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    lab.put(keys.derived("lab", "knob", "a"), {"t": time.time(), "seq": 1, "v": 1.0})
    wait_for(lambda: held, what="the map's joints/set at the owner")
    owner.put(keys.event("pepper", "command"), {"t": time.time(), "kind": "command", "verb": "stop", "args": {},
                                                "ok": True})
    wait_for(lambda: "pepper" in node._drive.halted, what="the stop heard")
    assert stops == []
    query = held.pop()
    query.reply(keys.command("pepper", "joints/set"), codec.encode(ok_reply("joints/set", {})))
    del query
    wait_for(lambda: stops, what="the node's own stop")
    assert node.stats["stops_sent"] == 1
    queryable.undeclare()
