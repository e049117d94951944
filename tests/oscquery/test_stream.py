"""Issue 16: the WebSocket of the OSCQuery server — LISTEN streams a joint as binary OSC,
nearly every value the robot publishes, IGNORE ends it; PATH_ADDED, PATH_REMOVED and PATH_CHANGED as
robots come, go and change; bad input is counted and leaves everything up; a value sent
to a writable address at HOST_INFO's OSC port moves the simulated robot."""

from __future__ import annotations

import itertools
import json
import socket
import statistics
import struct
import time
from collections import Counter

from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus.adapters.oscquery import server
from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import codec, load_model

from ..conftest import wait_for
from .conftest import RATE, Served, Socket, serve, stalled

HEAD = "/pepper/joints/HeadYaw"


def osc(socket_) -> list[OscMessage]:
    return [OscMessage(m) for m in list(socket_.messages) if isinstance(m, bytes)]


class Published:
    """One joint's values as the robot published them, seen on the test bus (rounded to
    float32, as OSC carries them): what a client should have got, by count, not by clock."""

    def __init__(self, served: Served, key: str) -> None:
        self.subscriber, self.queue = served.net.bus("watcher").subscribe(key)
        self.values: list[float] = []

    def take(self) -> list[float]:
        self.values += [_f32(codec.decode(payload)["v"]) for _, payload in self.queue.drain(timeout=0)]
        return self.values


def _f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def completeness(published: Published, client: Socket, count: int = 100) -> tuple[int, int]:
    """``(got, count)``: how many of the next ``count`` values the robot publishes (once the
    client gets values) reach the client. The window is over once the client has one of the
    values published after it (the values come in order). HeadYaw's values tell frames apart:
    the idle robot's head never stops."""
    wait_for(lambda: osc(client), what="a first value")
    begun = len(published.take())
    end = begun + count
    wait_for(lambda: len(published.take()) >= end + 20, 30, f"{count + 20} values published")
    window, after = published.values[begun:end], set(published.values[end:end + 20])
    assert len(set(window)) >= 0.9 * count, "HeadYaw held still: its values no longer tell frames apart"

    def received() -> Counter[float]:
        return Counter(m.params[0] for m in osc(client) if m.address == HEAD)
    wait_for(lambda: not after.isdisjoint(received()), 30, "a value published after the window")
    got = received()
    return sum(min(n, got[v]) for v, n in Counter(window).items()), count


def test_listen_streams_every_value_of_a_joint_and_ignore_ends_it(served, websocket, figure):
    published = Published(served, "pepper/joints/HeadYaw")
    client = websocket(served.url)
    client.send({"COMMAND": "LISTEN", "DATA": HEAD})
    got, count = completeness(published, client)
    values = [m for m in osc(client) if m.address == HEAD]
    assert all(len(m.params) == 1 and isinstance(m.params[0], float) for m in values)
    assert got >= 0.9 * count, dict(served.node.stats.items())  # completeness, not timing
    figure("HeadYaw values over WebSocket", 100 * got / count, f"% of {count} published (robot {RATE} frames/s)")
    # IGNORE, then LISTEN to another joint: once that one streams, HeadYaw no longer does
    client.send({"COMMAND": "IGNORE", "DATA": HEAD})
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/joints/HeadPitch"})
    wait_for(lambda: sum(m.address == "/pepper/joints/HeadPitch" for m in osc(client)) >= 10, what="HeadPitch")
    after = osc(client)
    switched = next(i for i, m in enumerate(after) if m.address == "/pepper/joints/HeadPitch")
    assert all(m.address == "/pepper/joints/HeadPitch" for m in after[switched:])
    assert served.node.stats["sent"] >= len(values)


def test_stream_rate_measured(served, websocket, figure):
    """The gaps between values of one joint over the WebSocket, against the robot's period
    (measured, not asserted: the assertion is that nearly every published value came)."""
    published = Published(served, "pepper/joints/HeadYaw")
    client = websocket(served.url)
    client.send({"COMMAND": "LISTEN", "DATA": HEAD})
    wait_for(lambda: osc(client), what="a first value")
    begun = time.monotonic()
    got, count = completeness(published, client, 150)
    took = time.monotonic() - begun
    assert got >= 0.9 * count
    stamps = [at for at, m in zip(list(client.arrived), list(client.messages), strict=False)
              if isinstance(m, bytes) and at >= begun]
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    figure("median gap between HeadYaw values", statistics.median(gaps) * 1000, f"ms (robot period {1000 / RATE:g} ms)")
    figure("values per second", len(stamps) / took, f"/s (robot {RATE} frames/s)")


def test_robots_coming_going_and_changing_are_announced(served, websocket):
    client = websocket(served.url)
    root = {"COMMAND": "PATH_CHANGED", "DATA": "/"}  # (for clients that handle only PATH_CHANGED)
    nao = served.net.sim("nao2", rate_hz=RATE)
    wait_for(lambda: {"COMMAND": "PATH_ADDED", "DATA": "/nao2"} in client.texts(), 10, "PATH_ADDED /nao2")
    wait_for(lambda: root in client.texts(), what="PATH_CHANGED / with the robot added")
    assert served.json("/nao2/joints/LKneePitch")["UNIT"] == ["angle.radian"]
    nao.stop()
    wait_for(lambda: {"COMMAND": "PATH_REMOVED", "DATA": "/nao2"} in client.texts(), 10, "PATH_REMOVED /nao2")
    wait_for(lambda: client.texts().count(root) == 2, what="PATH_CHANGED / with the robot removed")
    assert served.get("/nao2").status_code == 404
    assert "/pepper" not in [t["DATA"] for t in client.texts()]  # pepper stayed as it was


class Installing(SimRobot):
    """A simulated robot on which behaviors get installed while it runs."""

    installed: tuple[str, ...] = ()

    def behaviors(self) -> list[str]:  # (read at each info query)
        return [*super().behaviors(), *self.installed]


def test_behaviors_installed_are_announced_as_path_changed(net, websocket):
    robot = net.start(Installing(SimConfig(robot="pepper3", rate_hz=RATE), name="pepper3"))
    served = serve(net)
    served.wait_node("/pepper3/cmd/behavior/run")
    client = websocket(served.url)
    robot.installed = ("my/new_behavior",)
    wait_for(lambda: {"COMMAND": "PATH_CHANGED", "DATA": "/pepper3"} in client.texts(), 10, "PATH_CHANGED")
    assert "my/new_behavior" in served.json("/pepper3/cmd/behavior/run")["RANGE"][0]["VALS"]


def test_bad_websocket_input_is_counted_and_everything_stays_up(served, websocket, caplog):
    client = websocket(served.url)
    fake = "/x\x1b[2J\nsonibus: error: fake"  # a fake error line and a terminal escape in a LISTENed path
    bad = [json.dumps({"COMMAND": "LISTEN", "DATA": fake}), "junk", "[1, 2]",
           '{"COMMAND": "DANCE", "DATA": "/pepper"}', '{"COMMAND": "LISTEN", "DATA": 5}',
           '{"COMMAND": "LISTEN"}', "x" * 100_000, "[" * 3000, "{" * 3000,
           *(json.dumps({"COMMAND": "LISTEN", "DATA": path}) for path in
             ("/pepper/joints/Head Yaw", "/pepper/#bundle", "/" + "a" * 1024, "pepper/joints/HeadYaw"))]
    for text in bad:
        client.send(text)
    client.send(b"\x00\xff binary")
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/joints/NoSuchJoint"})  # not bad: it may come
    wait_for(lambda: served.node.stats["bad"] >= len(bad) + 1, what="every bad message counted")
    assert served.node.stats["bad"] == len(bad) + 1 and served.node.stats["errors"] == 0
    wait_for(lambda: served.node.server.listened == {"/pepper/joints/NoSuchJoint": 1}, what="only the good LISTEN kept")
    said = "\n".join(r.getMessage() for r in caplog.records)
    assert "\x1b" not in said and "\nsonibus: error: fake" not in said
    client.send({"COMMAND": "LISTEN", "DATA": HEAD})  # the same connection still works
    wait_for(lambda: osc(client), what="values after bad input")
    assert not client.closed and served.node.state == "running"
    # a client that goes away mid-stream
    leaving = websocket(served.url)
    leaving.send({"COMMAND": "LISTEN", "DATA": HEAD})
    wait_for(lambda: osc(leaving), what="values to the leaving client")
    leaving.close()
    wait_for(lambda: served.node.server.clients == 1, what="the leaving client gone")
    before = len(osc(client))
    wait_for(lambda: len(osc(client)) > before + 10, what="values still streaming to the other client")
    assert served.get("/pepper").status_code == 200


def test_a_value_sent_to_a_writable_address_moves_the_robot(served):
    """The elbow: the idle robot's looking around and breathing move the head and shoulders."""
    host = served.json("/?HOST_INFO")
    target = served.json("/pepper/cmd/joints/set/RElbowRoll")
    assert target["ACCESS"] == 2 and target["TYPE"] == "f"
    elbow = "/pepper/joints/RElbowRoll"
    now = wait_for(lambda: served.json(elbow)["VALUE"][0], what="the elbow's angle")
    angle = 1.2 if now < 0.8 else 0.4
    builder = OscMessageBuilder(target["FULL_PATH"])
    builder.add_arg(angle, "f")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.sendto(builder.build().dgram, (host["OSC_IP"], host["OSC_PORT"]))
    wait_for(lambda: abs(served.json(elbow)["VALUE"][0] - angle) < 0.05, 10, f"RElbowRoll near {angle}")


def test_a_robot_whose_info_is_unusable_is_left_out_with_a_warning(served, caplog):
    """A robot on the bus whose info the gate refuses, and one whose info the namespace
    cannot use (a derived value of 65 numbers): both left out, the node and pepper served."""
    from sonibus.bus import codec
    bus = served.net.bus("liar")
    asked = []

    def answer(query):
        asked.append(query)
        query.reply("liar2/info", codec.encode(info))
    info = {**served.net.bus("asker").query("pepper/info")[0], "robot": "liar2", "owner": {"host": "h", "node": "n"},
            "derived": [{"name": "hand/L", "key": "liar2/derived/hand/L", "unit": "m", "size": 65}]}
    since = int(time.time() * 1000)  # (a claim's time must make sense: bus/ownership.py)
    entities = [bus.serve("liar/info", lambda q: q.reply("liar/info", b"\xc1 not msgpack")),
                bus.token(f"sonibus/robots/liar/{since}/h/n"),
                bus.serve("liar2/info", answer),
                bus.token(f"sonibus/robots/liar2/{since}/h/n")]
    try:
        wait_for(lambda: served.node.stats["robots_left_out"] >= 1, 10, "liar2 left out")
        wait_for(lambda: any("liar/info unusable" in r.getMessage() for r in caplog.records), 10, "liar warned")
        # (counted, then warned on the node's thread: the count may be seen first)
        wait_for(lambda: any("'liar2' left out" in r.getMessage() for r in caplog.records), 10, "liar2 warned")
        wait_for(lambda: len(asked) >= 3, 20, "liar2's info asked again twice")
        assert served.node.stats["robots_left_out"] == 1  # a robot, not the times it was asked
        assert served.get("/liar").status_code == 404 and served.get("/liar2").status_code == 404
        assert served.node.state == "running" and served.get("/pepper/joints/HeadYaw").status_code == 200
    finally:
        for entity in entities:
            entity.undeclare()


def test_events_are_served_and_streamed(served, websocket):
    client = websocket(served.url)
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/events/behavior"})
    host = served.json("/?HOST_INFO")
    name = served.json("/pepper/cmd/behavior/run")["RANGE"][0]["VALS"][0]
    builder = OscMessageBuilder("/pepper/cmd/behavior/run")
    builder.add_arg(name, "s")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.sendto(builder.build().dgram, (host["OSC_IP"], host["OSC_PORT"]))
    wait_for(lambda: any(m.params == [name, "started"] for m in osc(client)), 10, "the behavior's start, streamed")
    assert served.json("/pepper/events/behavior?VALUE")["VALUE"][0] == name


def test_event_kinds_outside_the_table_are_served_once_seen_and_streamed(served, websocket, caplog):
    """A features node's motion onsets (a kind the robot's info does not name): served once
    seen, typed by its fields, announced and streamed; one that does not fit is counted."""
    client = websocket(served.url)
    motion = "/pepper/events/motion"
    client.send({"COMMAND": "LISTEN", "DATA": motion})  # (not served yet: kept)
    features = served.net.bus("features")
    onset = {"t": time.time(), "kind": "motion", "chain": "RArm", "seq": 7, "state": "onset"}
    wait_for(lambda: features.put("pepper/events/motion", onset) or  # (again until the node's subscription is known)
             any(m.address == motion and m.params == ["RArm", 7, "onset"] for m in osc(client)), 10,
             "the onset streamed")
    assert {"COMMAND": "PATH_ADDED", "DATA": motion} in client.texts()
    assert {"COMMAND": "PATH_CHANGED", "DATA": "/pepper/events"} in client.texts()
    node = served.json(motion)
    assert (node["TYPE"], node["ACCESS"], node["VALUE"]) == ("sis", 1, ["RArm", 7, "onset"])
    assert node["RANGE"][2] == {"VALS": ["onset", "offset"]} and "chain" in node["DESCRIPTION"]
    features.put("pepper/events/motion", {**onset, "seq": 8, "extra": 1.5})  # a field more: no longer "sis"
    wait_for(lambda: served.node.stats["unfit"] == 1, what="the event that does not fit counted")
    wait_for(lambda: any(f"not served: '{motion}'" in r.getMessage() and "'sis'" in r.getMessage()
                         for r in caplog.records), what="the event that does not fit warned (after it was counted)")
    assert served.json(motion)["VALUE"] == ["RArm", 7, "onset"]


def test_a_client_that_does_not_read_loses_values_not_the_node(served, websocket):
    """A client whose socket is never read: once the kernel's buffers are full its backlog
    overflows (counted as ws_dropped, apart from the node's own queue) while another client
    keeps getting values and HTTP answers. A fast robot (a NAO at 500 frames/s) fills the
    buffers in seconds."""
    served.net.sim("fast", model="nao", rate_hz=500)
    served.wait_node("/fast/joints/HeadYaw")
    with stalled(served.url, [f"/fast/joints/{joint}" for joint in load_model("nao").joint_names]):
        wait_for(lambda: served.node.stats["ws_dropped"] > 0, 60, "values dropped for the stalled client",
                 lambda: str(dict(served.node.stats.items())))
        client = websocket(served.url)
        client.send({"COMMAND": "LISTEN", "DATA": HEAD})
        wait_for(lambda: len(osc(client)) >= 10, what="values to a client that reads")
        assert served.get("/pepper").status_code == 200


def test_stop_is_not_held_by_a_client_that_does_not_read(net, caplog, figure):
    """Closing a client whose socket is full would wait for ever: it is cut after the close's
    wait, so the node stops within its time and no thread is left behind."""
    net.sim("fast", model="nao", rate_hz=500)
    served = serve(net)
    served.wait_node("/fast/joints/HeadYaw")
    with stalled(served.url, [f"/fast/joints/{joint}" for joint in load_model("nao").joint_names]):
        wait_for(lambda: served.node.stats["ws_dropped"] > 0, 60, "the stalled client's buffers full")
        begun = time.monotonic()
        served.node.stop()
        took = time.monotonic() - begun
    assert not [r.getMessage() for r in caplog.records if "did not stop" in r.getMessage()]
    assert took < 3.0  # (the node's time to stop; it hung 2 s per thread before)
    figure("stop with a client that does not read", took, "s")


def test_a_client_that_vanished_is_dropped_and_listens_are_bounded(served, websocket, monkeypatch):
    """A client that never answers the server's pings (gone without closing: a cable pulled)
    is dropped, one that answers stays; a client may LISTEN to MAX_LISTENS paths, no more."""
    monkeypatch.setattr(server, "HEARTBEAT_S", 0.4)  # (10 s in use)
    monkeypatch.setattr(server, "MAX_LISTENS", 3)
    client = websocket(served.url)
    with stalled(served.url, []):
        wait_for(lambda: served.node.server.clients == 2, what="both clients connected")
        wait_for(lambda: served.node.server.clients == 1, 10, "the client that does not answer dropped")
    for joint in ("HeadYaw", "HeadPitch", "LHand", "RHand"):
        client.send({"COMMAND": "LISTEN", "DATA": f"/pepper/joints/{joint}"})
    wait_for(lambda: served.node.stats["bad"] == 1, what="the fourth LISTEN refused")
    assert len(served.node.server.listened) == 3 and not client.closed


def test_queries_over_the_websocket_are_answered_as_text(served, websocket):
    """libossia's clients (ossia score) ask for nodes over the WebSocket, a path as text."""
    client = websocket(served.url)
    client.send("/pepper/joints/HeadYaw")
    client.send("/pepper/joints/HeadYaw?UNIT")
    client.send("/?HOST_INFO")
    wait_for(lambda: len(client.texts()) >= 3, what="three answers")
    node, unit, host = client.texts()[:3]
    assert node["FULL_PATH"] == HEAD and node["RANGE"] == served.json(HEAD)["RANGE"]
    assert unit == {"UNIT": ["angle.radian"]} and host["OSC_PORT"] == served.gateway.udp_address[1]
    client.send("/pepper/joints/Tail")
    wait_for(lambda: served.node.stats["bad"] == 1, what="an unknown path counted")
