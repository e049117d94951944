"""Issue 16: a client that is not ours (python-oscquery, requests) reads the namespace of
a simulated Pepper: joints with the robot's limits and units, events, the gateway's
commands with their choices, HOST_INFO, attribute queries and errors."""

from __future__ import annotations

import json
import socket

from pythonoscquery.osc_query_client import OSCQueryClient
from pythonoscquery.shared.osc_access import OSCAccess
from zeroconf import ServiceInfo

from sonibus import schemas
from sonibus.adapters.osc import routes
from sonibus.adapters.oscquery.namespace import EVENT_ARGS
from sonibus.bus import load_model, robot_info

from ..conftest import wait_for
from .conftest import Served, serve


def client(served: Served) -> OSCQueryClient:
    """python-oscquery's client, pointed at the server as its browser would find it."""
    port = int(served.url.rsplit(":", 1)[1])
    info = ServiceInfo("_oscjson._tcp.local.", "test._oscjson._tcp.local.", port=port,
                       addresses=[socket.inet_aton("127.0.0.1")])
    return OSCQueryClient(info)


def test_python_oscquery_reads_the_whole_tree_and_host_info(served):
    oscquery = client(served)
    root = oscquery.query_node("/")
    paths = {node.full_path: node for node in root}
    pepper = load_model("pepper")
    for joint in pepper.joint_names:
        assert paths[f"/pepper/joints/{joint}"].access is OSCAccess.READONLY_VALUE
        assert paths[f"/pepper/cmd/joints/set/{joint}"].access is OSCAccess.WRITEONLY_VALUE
    for kind in EVENT_ARGS:
        assert paths[f"/pepper/events/{kind}"].access is OSCAccess.READONLY_VALUE
    for route in routes.ROUTES:
        if route is not routes.PER_JOINT:
            assert route.address("pepper") in paths
    host = oscquery.get_host_info()
    assert host.osc_port == served.gateway.udp_address[1]
    assert (host.osc_ip, host.osc_transport) == ("127.0.0.1", "UDP")
    assert host.name == "sonibus"
    assert all(host.extensions[e] for e in ("ACCESS", "VALUE", "RANGE", "DESCRIPTION", "UNIT", "LISTEN",
                                            "PATH_ADDED", "PATH_REMOVED", "PATH_CHANGED"))


def test_joint_ranges_units_and_values_are_the_robots(served):
    for spec in load_model("pepper").joints:
        node = served.json(f"/pepper/joints/{spec.name}")
        assert node["TYPE"] == "f"
        assert node["RANGE"] == [{"MIN": spec.min, "MAX": spec.max}]
        assert node["UNIT"] == ["fraction" if spec.name.endswith("Hand") else "angle.radian"]  # (the spec's name)
        assert node["ACCESS"] == 1 and spec.name in node["DESCRIPTION"]
    wait_for(lambda: isinstance(served.json("/pepper/joints/HeadYaw")["VALUE"][0], float), what="a current value")
    value = served.json("/pepper/joints/HeadYaw")["VALUE"][0]
    assert -2.09 < value < 2.09


def test_commands_carry_the_robots_choices_and_the_schemas_bounds(served):
    info = robot_info(served.net.bus("asker"), "pepper")
    pepper = load_model("pepper")
    run = served.json("/pepper/cmd/behavior/run")
    assert (run["TYPE"], run["ACCESS"], run["RANGE"]) == ("s", 2, [{"VALS": info["behaviors"]}])
    assert len(info["behaviors"]) >= 5
    assert served.json("/pepper/cmd/posture")["RANGE"] == [{"VALS": info["postures"]}]
    assert served.json("/pepper/cmd/joints/set")["RANGE"][0] == {"VALS": list(pepper.joint_names)}
    stiffness = served.json("/pepper/cmd/stiffness")
    assert stiffness["TYPE"] == "sf" and stiffness["RANGE"][1] == {"MIN": 0, "MAX": 1}
    assert {"HeadYaw", "RArm", "Body"} <= set(stiffness["RANGE"][0]["VALS"])
    per_joint = served.json("/pepper/cmd/joints/set/RElbowRoll")
    spec = pepper.joint("RElbowRoll")
    assert per_joint["RANGE"] == [{"MIN": spec.min, "MAX": spec.max}] and per_joint["TYPE"] == "f"
    assert spec.min <= per_joint["VALUE"][0] <= spec.max
    for verb in ("stop", "behavior/stop", "behavior/list"):
        assert served.json(f"/pepper/cmd/{verb}")["TYPE"] == "N"
        assert served.json(f"/pepper/cmd/{verb}")["VALUE"] == [None]
    assert served.json("/pepper/events/connection")["RANGE"] == [{"VALS": ["connecting", "connected", "not_answering",
                                                                          "lost"]}]
    assert served.json("/pepper/events/command")["TYPE"] == "si"


def test_attribute_queries_and_errors(served):
    assert served.json("/pepper/joints/HeadYaw?UNIT") == {"UNIT": ["angle.radian"]}
    hand = load_model("pepper").joint("LHand")
    assert served.json("/pepper/joints/LHand?RANGE") == {"RANGE": [{"MIN": hand.min, "MAX": hand.max}]}
    assert served.json("/pepper/cmd/say?TYPE") == {"TYPE": "s"}
    assert set(served.json("/pepper?CONTENTS")["CONTENTS"]) == {"joints", "events", "cmd", "program"}
    assert served.json("/pepper/program/scenario?TYPE") == {"TYPE": "s"}  # (a show's scenarios, via the gateway)
    assert served.get("/pepper/cmd/stop?RANGE").status_code == 204      # a node without it
    assert served.get("/pepper/cmd/say?VALUE").status_code == 204        # write-only: no value to read
    assert served.json("/pepper/events/speech?VALUE") == {}               # no value yet
    assert served.get("/pepper/joints/HeadYaw?BOGUS").status_code == 400
    assert served.get("/pepper/joints/Tail").status_code == 404
    assert served.get("/nao").status_code == 404
    assert served.json("/pepper/joints/HeadYaw/") ["FULL_PATH"] == "/pepper/joints/HeadYaw"
    assert "NaN" not in served.get("/").text
    assert served.node.stats["http_requests"] >= 10


def test_normalized_values_are_fractions_of_the_range(net):
    net.sim("pepper", rate_hz=50, idle=True)
    served = serve(net, values="normalized")
    node = served.wait_node("/pepper/joints/HeadYaw")
    assert node["RANGE"] == [{"MIN": 0.0, "MAX": 1.0}] and "UNIT" not in node
    value = wait_for(lambda: served.json("/pepper/joints/HeadYaw?VALUE").get("VALUE", [None])[0], what="a value")
    spec = load_model("pepper").joint("HeadYaw")
    assert 0.1 < value < 0.9  # the sim's head looks around 0 rad, the middle of its range
    # commands stay in the robot's units: the gateway takes them so
    assert served.json("/pepper/cmd/joints/set/HeadYaw")["RANGE"] == [{"MIN": spec.min, "MAX": spec.max}]


def test_derived_values_carry_their_units_and_ranges(net):
    from sonibus.adapters.features import Features, FeaturesConfig
    net.sim("pepper", rate_hz=50, idle=True)
    net.start(Features(FeaturesConfig(robots="pepper"), name="features"))
    served = serve(net)
    node = served.wait_node("/pepper/derived/hand/L")
    asker = served.net.bus("asker")
    info = wait_for(lambda: {d["name"]: d for r in asker.query("pepper/info/derived") for d in r["derived"]},
                    what="derived info")
    hand = info["hand/L"]
    assert hand["unit"] == "m" and node["TYPE"] == "f" * hand["size"] and node["UNIT"] == ["distance.m"] * hand["size"]
    speed = served.wait_node("/pepper/derived/hand_speed/L")
    assert info["hand_speed/L"]["unit"] == "m/s" and speed["UNIT"] == ["speed.m/s"]
    if "min" in hand:
        assert node["RANGE"] == [{"MIN": hand["min"], "MAX": hand["max"]}] * hand["size"]
    wait_for(lambda: None not in served.json("/pepper/derived/hand/L?VALUE")["VALUE"], what="a hand position")
    assert json.loads(served.get("/pepper/derived").text)["CONTENTS"]


def test_containers_are_described_and_help_reads_the_schemas(served):
    tree = served.json("/")
    containers = []

    def walk(node):
        if "CONTENTS" in node:
            containers.append(node)
            for child in node["CONTENTS"].values():
                walk(child)
    walk(tree)
    assert len(containers) >= 8  # /, /pepper, its joints, events, cmd, cmd/behavior, cmd/joints, cmd/joints/set
    assert all(node["DESCRIPTION"] for node in containers), [n["FULL_PATH"] for n in containers
                                                             if not n.get("DESCRIPTION")]
    assert "joint angles" in served.json("/pepper/joints")["DESCRIPTION"]
    speed = schemas.command_schema("joints/set")["properties"]["speed"]["default"]
    assert f"(default {speed:g})" in served.json("/pepper/cmd/joints/set/HeadYaw")["DESCRIPTION"]
