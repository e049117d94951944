"""Maps added, removed and retargeted while the node runs (``<node>/maps/add``, ``remove``,
an ``edit`` of ``target``): checked as the file is, the other maps running on; undo takes
each back; save writes them into the file with its comments; a map that drives a robot,
added after a stop, is halted until resumed like the others."""

from __future__ import annotations

import json
import time
import tomllib

from sonibus.bus import client, keys

from ..conftest import run_cli, wait_for
from .test_drive import Rig
from .test_edit import ask, first_output, running

SWING = {"source": "pepper/joints/HeadYaw", "from": [-1, 1], "to": [0, 10], "unit": "cc"}


def outputs(head, name: str) -> list:
    return head.outputs.on(f"sound/derived/map/{name}")


def described(bus) -> list[str]:
    return sorted(d["name"] for reply in bus.query(keys.derived_info("sound"), timeout=2.0) for d in reply["derived"])


def test_a_map_added_runs_at_once_is_described_undone_and_saved(net, owner, tmp_path):
    path, _, head = running(net, owner, tmp_path)
    reply = ask(head.watch, "add", {"map": "swing", "table": SWING})
    assert reply["ok"] and reply["result"]["added"], reply
    assert first_output(head, 0.0, 0.0) == 50.0  # (yaw runs on)
    wait_for(lambda: head.output(0.5, "swing") == 7.5, what="the added map's output")
    assert described(head.watch) == ["map/swing", "map/yaw"]  # (quiet is disabled: no output)
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["yaw", "quiet", "swing"]

    saved = ask(head.watch, "save")
    assert saved["ok"], saved
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# the museum's sound (a comment the save keeps)\n")
    assert "[nodes.sound.maps.yaw]   # the head turns a filter\n" in text
    assert tomllib.loads(text)["nodes"]["sound"]["maps"]["swing"] == SWING

    undone = ask(head.watch, "undo", {})
    assert undone["ok"] and undone["result"]["table"] is None, undone
    assert "map/swing" not in described(head.watch)
    assert ask(head.watch, "save")["ok"]
    assert "swing" not in tomllib.loads(path.read_text(encoding="utf-8"))["nodes"]["sound"]["maps"]


def test_a_bad_add_is_refused_in_one_line_and_the_others_run_on(net, owner, tmp_path):
    _, _, head = running(net, owner, tmp_path)
    for args, reason in [
        ({"map": "swing", "table": {**SWING, "curve": "expo"}}, "'expo' is not a curve"),
        ({"map": "yaw", "table": SWING}, "add: node 'sound' already has a map 'yaw' — edit it, or remove it first"),
        ({"map": "swing", "table": {**SWING, "source": "nao/joints/HeadYaw"}},
         "source 'nao/joints/HeadYaw' is not among those this node listens to — save, then restart the run"),
        ({"map": "map", "table": SWING}, "'map' is the name of the node's own events"),
        ({"map": "swing"}, "add: arguments:"),
    ]:
        reply = ask(head.watch, "add", args)
        assert not reply["ok"] and reason in reply["error"]["message"], (args, reply)
        assert "\n" not in reply["error"]["message"]
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["yaw", "quiet"]
    assert first_output(head, 0.0, time.time()) == 50.0


def test_a_map_removed_stops_and_undo_brings_it_back(net, owner, tmp_path):
    path, _, head = running(net, owner, tmp_path)
    assert first_output(head, 0.0, time.time()) == 50.0
    reply = ask(head.watch, "remove", {"map": "yaw"})
    assert reply["ok"] and reply["result"] == {"map": "yaw", "removed": True}, reply
    removed = time.time()
    for _ in range(10):
        head.fake.frame(time.time(), {"HeadYaw": 0.0})
        time.sleep(0.02)
    assert [m for m in outputs(head, "yaw") if m["t"] > removed] == []
    assert "map/yaw" not in described(head.watch)
    assert ask(head.watch, "remove", {"map": "yaw"})["error"]["message"] == \
        "no map 'yaw' in node 'sound' — maps: quiet"
    assert ask(head.watch, "save")["ok"]
    assert "yaw" not in tomllib.loads(path.read_text(encoding="utf-8"))["nodes"]["sound"]["maps"]
    assert ask(head.watch, "undo", {"map": "yaw"})["ok"]
    assert first_output(head, 0.0, time.time()) == 50.0


def test_a_map_retargeted_or_added_live_with_a_robot_target_is_halted_until_resumed(net):
    rig = Rig(net)
    wait_for(lambda: rig.bus.query(keys.program("moves", "status"), timeout=0.5), what="the map node")
    # retargeted: map 'look' now turns the head's pitch, at most 5 commands a second
    edited = client_ask(rig, "edit", {"map": "look", "set": {
        "target": {"robot": "pepper", "command": "joints/set", "joint": "HeadPitch", "hz": 5}}})
    assert edited["ok"], edited
    rig.knob("a", 1.0)
    sent = wait_for(lambda: rig.commands("joints/set"), what="the retargeted map's command")
    assert sent[0]["args"]["names"] == ["HeadPitch"]

    assert client.send_command(rig.bus, "pepper", "stop")["held"] is True
    wait_for(lambda: "pepper" in rig.node.halted(), what="the stop heard")
    tilt = {"source": "lab/derived/knob/b", "from": [0, 1], "to": [-0.2, 0.2],
            "target": {"robot": "pepper", "command": "joints/set", "joint": "HeadYaw"}}
    added = client_ask(rig, "add", {"map": "tilt", "table": tilt})
    assert added["ok"], added
    before = len(rig.commands("joints/set"))
    halted = rig.node.stats["halted"]
    rig.knob("b", 0.5)
    rig.knob("a", 0.0)
    wait_for(lambda: rig.node.stats["halted"] >= halted + 2, what="both maps held back")
    assert len(rig.commands("joints/set")) == before
    assert rig.program("resume", {})["resumed"] == ["pepper"]
    rig.knob("b", 1.0)
    wait_for(lambda: any(c["args"]["names"] == ["HeadYaw"] for c in rig.commands("joints/set")[before:]),
             what="the added map driving after the resume")


def client_ask(rig, verb: str, args: dict) -> dict:
    answers = rig.bus.query(keys.maps("moves", verb), args, timeout=5.0)
    assert len(answers) == 1, answers
    return answers[0]


def test_sonibus_map_add_and_remove(net, owner, tmp_path):
    """The terminal's way: each argument a line of the map's table; a refusal in one line, exit not 0."""
    _, _, head = running(net, owner, tmp_path)
    added = run_cli("map", "add", "sound", "swing", 'source = "pepper/joints/HeadYaw"', "from = [-1, 1]",
                    "to = [0, 10]", *net.cli_args())
    assert added.returncode == 0, added.stderr
    assert json.loads(added.stdout)["added"] is True
    wait_for(lambda: head.output(0.5, "swing") == 7.5, what="the added map's output")
    refused = run_cli("map", "add", "sound", "twirl", 'source = "pepper/joints/HeadYaw"', 'curve = "expo"',
                      *net.cli_args())
    assert refused.returncode != 0
    assert "'expo' is not a curve" in refused.stderr and len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    bad = run_cli("map", "add", "sound", "twirl", "source = pepper", *net.cli_args())
    assert bad.returncode != 0 and "the map's table is not TOML" in bad.stderr, bad.stderr
    removed = run_cli("map", "remove", "sound", "swing", *net.cli_args())
    assert removed.returncode == 0, removed.stderr
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["yaw", "quiet"]
