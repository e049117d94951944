"""The operator page's mappings panel in a real browser (headless Chromium): a breakpoint
dragged changes the map's output from the next frame on, a refused edit shows its reason
in place while the map runs as it was, and save writes the file that a restart runs."""

from __future__ import annotations

import threading
import time
import tomllib
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys

from sonibus.adapters.map.curves import Points
from sonibus.bus import client

from ..conftest import wait_for
from ..features.conftest import owner  # noqa: F401  (the owner fixture)
from ..map.conftest import pose
from ..map.test_drive import Rig
from ..map.test_edit import FILE, Head, ask, first_output, start
from .conftest import TOKEN, start_web

POINT = '.map[data-map="yaw"] .point[data-index="1"]'


def type_in(box, value: str) -> None:
    """``value`` typed over what a field holds (focused first: the panel leaves a focused field
    alone when the node's maps come), then Tab: its change is sent."""
    box.click()
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(value, Keys.TAB)


@pytest.fixture
def head(net, owner) -> Iterator[Head]:  # noqa: F811
    """pepper's head at yaw 0 (x = 0.5 for the map), a frame every 20 ms until the test ends."""
    made = Head(net, owner)
    stop = threading.Event()

    def feed() -> None:
        while not stop.wait(0.02):
            made.fake.frame(time.time(), pose(HeadYaw=0.0))
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        yield made
    finally:
        stop.set()
        feeder.join(2.0)


def test_a_curve_dragged_on_the_page_runs_at_once_survives_save_and_a_restart(net, head, browser, tmp_path):
    path = tmp_path / "show.toml"
    path.write_text(FILE, encoding="utf-8")
    node = start(net, path)
    web = start_web(net, token=TOKEN)
    browser.open(f"{web.url}/?token={TOKEN}")
    browser.wait(lambda: browser.attribute("#connection", "data-state") == "connected", "the page connected")
    browser.wait(lambda: browser.text('.map[data-map="yaw"] .map-out') == "50", "the yaw map's live output, 50")
    assert browser.text('.map[data-map="yaw"] .map-in') == "0.500"
    assert browser.js("return document.querySelector('.map[data-map=\"quiet\"] .map-enabled').checked") is False

    # a refused edit: its reason under the map, the map running as it was
    type_in(browser.find('.map[data-map="yaw"] .map-to-low'), "100")
    browser.wait(lambda: "[100, 100] is no range" in (browser.text('.map[data-map="yaw"] .map-error') or ""),
                 "the refusal shown in place")
    assert browser.text('.map[data-map="yaw"] .map-error') == \
        "map 'yaw': key 'maps.yaw.to': [100, 100] is no range: give two different values"
    assert first_output(head, 0.0, time.time()) == 50.0

    # the middle breakpoint dragged up: the next frame goes through the new curve
    ActionChains(browser.driver).click_and_hold(browser.find(POINT)).move_by_offset(0, -20) \
        .move_by_offset(0, -22).release().perform()
    table = wait_for(lambda: (t := ask(head.watch, "list")["result"]["maps"][0]["table"])["points"][1][1] > 0.8
                     and t, what="the dragged point at the node")
    applied = time.time()
    x, y = table["points"][1]
    assert abs(x - 0.5) < 0.01 and 0.85 < y < 0.95, table  # (42 px up of the curve's 104: 0.4; a pixel's rounding)
    expected = 100 * Points(((0, 0), (x, y), (1, 1)))(0.5)
    assert first_output(head, 0.0, applied) == pytest.approx(expected, rel=1e-12)
    browser.wait(lambda: browser.text('.map[data-map="yaw"] .map-error') == "", "the refusal cleared")
    shown = browser.wait(lambda: (browser.text('.map[data-map="yaw"] .map-out') or "50") != "50" and
                         browser.text('.map[data-map="yaw"] .map-out'), "the new output on the page")
    assert float(shown) == pytest.approx(expected, rel=1e-5)
    browser.screenshot("mapping-panel.png", tmp_path, publish=True)

    # the source's range typed (yaw 0 is now its bottom: the curve's start, 0), then undone
    for field, value in (("low", "0"), ("high", "1")):
        type_in(browser.find(f'.map[data-map="yaw"] .map-from-{field}'), value)
    wait_for(lambda: ask(head.watch, "list")["result"]["maps"][0]["table"]["from"] == [0, 1], what="from = [0, 1]",
             explain=lambda: f"{ask(head.watch, 'list')['result']['maps'][0]['table']}; {browser.text('#status')}")
    assert first_output(head, 0.0, time.time()) == 0.0
    browser.find('.map[data-map="yaw"] .map-undo').click()
    wait_for(lambda: ask(head.watch, "list")["result"]["maps"][0]["table"]["from"] == [-1, 1], what="the undo")
    assert first_output(head, 0.0, time.time()) == pytest.approx(expected, rel=1e-12)

    browser.find('.map-node[data-node="sound"] .map-save').click()
    browser.wait(lambda: (browser.text('.map-node[data-node="sound"] .map-saved') or "").startswith("saved into"),
                 "the save's answer")
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# the museum's sound (a comment the save keeps)\n")
    assert "[nodes.sound.maps.yaw]   # the head turns a filter\n" in text
    assert "from = [-1, 1]           # radians: the show's span, not the joint's\n" in text
    assert tomllib.loads(text)["nodes"]["sound"]["maps"]["yaw"]["points"] == [[0, 0], [x, y], [1, 1]]

    node.stop()  # the run restarted: the map as saved
    start(net, path)
    assert first_output(head, 0.0, time.time()) == pytest.approx(expected, rel=1e-12)
    browser.wait(lambda: browser.attribute(POINT, "cy") is not None
                 and abs(float(browser.attribute(POINT, "cy")) - (120 - 8 - y * 104)) < 0.01,
                 "the page drawing the restarted node's curve")
    assert browser.errors() == []


def test_a_map_request_to_no_map_node_or_of_no_verb_is_answered_in_one_line(net, websocket):
    web = start_web(net, token=TOKEN)
    socket = websocket(f"{web.url.replace('http://', 'ws://')}/ws?token={TOKEN}")
    socket.wait("hello")
    socket.send({"type": "map", "id": 1, "node": "nosuch", "verb": "edit", "args": {"map": "x"}})
    socket.send({"type": "map", "id": 2, "node": "sound", "verb": "dance", "args": {}})
    socket.send({"type": "map", "id": 3, "node": "a/b", "verb": "edit", "args": {}})
    assert socket.wait("reply", id=1)["error"] == \
        "edit: no map node 'nosuch' on the bus (nosuch/maps/edit is served by nothing)"
    assert socket.wait("reply", id=2)["error"] == \
        "map: unknown verb 'dance' — a map node takes list, edit, learn, undo, save, add, remove, resume"
    assert socket.wait("reply", id=3)["error"].startswith("map: node name 'a/b' must be non-empty without '/'")


def test_a_stop_shows_the_halted_maps_and_the_pages_resume_lets_them_drive_again(net, browser):
    """The robot's stop halts the maps that drive it; the panel says so with a resume button that
    asks <node>/program/resume (as `sonibus resume` does) and shows the node's answer as it came."""
    rig = Rig(net)  # a simulated pepper, map node 'moves' whose map 'look' turns its head from knob 'a'
    web = start_web(net, token=TOKEN)
    browser.open(f"{web.url}/?token={TOKEN}")
    halted = '.map-node[data-node="moves"] .map-halted'
    browser.wait(lambda: browser.attribute(halted, "hidden") is not None, "the moves node's block, nothing halted")
    rig.knob("a", 1.0)
    wait_for(lambda: rig.commands("joints/set"), what="the map driving the head")

    stopped = client.send_command(rig.bus, "pepper", "stop")
    assert stopped["held"] is True
    browser.wait(lambda: browser.text(halted + " .map-halted-robots") == "pepper: halted by stop —"
                 and browser.attribute(halted, "hidden") is None, "the halt shown")
    assert browser.text(halted + " .map-resume") == "resume"
    sent = len(rig.commands("joints/set"))
    rig.knob("a", 0.0)
    wait_for(lambda: rig.node.stats["halted"] >= 1, what="the knob's value held back")
    assert len(rig.commands("joints/set")) == sent

    browser.find('.map-node[data-node="moves"] .map-resume').click()
    browser.wait(lambda: browser.text('.map-node[data-node="moves"] .map-resumed') == "resumed: pepper",
                 "the node's answer")
    assert rig.node.halted() == {}
    browser.wait(lambda: browser.attribute(halted, "hidden") is not None, "the halt line gone")
    rig.knob("a", 0.25)
    wait_for(lambda: len(rig.commands("joints/set")) > sent, what="the map driving the head again")
    # asked again with nothing halted (the button hidden: clicked by script): the answer says so
    browser.js("document.querySelector('.map-node[data-node=\"moves\"] .map-resume').click()")
    browser.wait(lambda: browser.text('.map-node[data-node="moves"] .map-resumed') == "resumed: none was halted",
                 "the second answer")
    assert browser.errors() == []


def test_maps_added_and_removed_on_the_page(net, head, browser, tmp_path):
    """A map added from the panel runs and shows its output; a refused add says why in place;
    remove takes a map out of the node and the panel; the node's undo brings it back."""
    path = tmp_path / "show.toml"
    path.write_text(FILE, encoding="utf-8")
    start(net, path)
    web = start_web(net, token=TOKEN)
    browser.open(f"{web.url}/?token={TOKEN}")
    block = '.map-node[data-node="sound"]'
    browser.wait(lambda: browser.text('.map[data-map="yaw"] .map-out') == "50", "the yaw map's live output")

    def add(name: str, source: str) -> None:
        for field, value in (("name", name), ("source", source)):
            box = browser.find(f"{block} .map-add-{field}")
            box.clear()
            box.send_keys(value)
        browser.find(f"{block} .map-add").click()

    add("swing", "pepper/joints/HeadRoll")
    browser.wait(lambda: "not among those this node listens to" in (browser.text(f"{block} .map-add-error") or ""),
                 "the refused add's reason")
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["yaw", "quiet"]
    add("swing", "pepper/joints/HeadYaw")
    browser.wait(lambda: (browser.text('.map[data-map="swing"] .map-out') or "–") != "–", "the added map's output")
    assert browser.text(f"{block} .map-add-error") == ""
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["yaw", "quiet", "swing"]

    browser.find('.map[data-map="yaw"] .map-remove').click()
    browser.wait(lambda: browser.text('.map[data-map="yaw"] .map-out') is None, "the removed map gone from the page")
    assert [m["name"] for m in ask(head.watch, "list")["result"]["maps"]] == ["quiet", "swing"]
    browser.find(f"{block} .map-node-undo").click()
    browser.wait(lambda: browser.text('.map[data-map="yaw"] .map-out') == "50", "the removal undone")
    assert browser.errors() == []
