"""The map node on a real bus: several sources combined, ranges from the robot's info,
thresholds as events, its outputs described on ``<node>/info/derived``, and what it
says when a source is silent or never came."""

from __future__ import annotations

import logging
import math
import threading
import time

from sonibus.adapters.map import MapNode
from sonibus.adapters.map.ranges import MAX_COMPONENTS, Ranges
from sonibus.bus import codec, keys

from ..conftest import wait_for
from ..features.conftest import model_info
from .conftest import map_node, pose

HEAD_YAW = next(j for j in model_info("pepper")["joints"] if j["name"] == "HeadYaw")

TEXT = '''[nodes.sound]
adapter = "map"
silent_s = 0.5
unseen_s = 0.5

[nodes.sound.maps.both]
sources = {a = "pepper/joints/HeadYaw", b = "pepper/joints/HeadPitch"}
expr = "a * b"
from = {b = [0, 1]}
to = [0, 100]
unit = "%"
threshold = [60, 40]
'''


class Listen:
    """Every sample on a key pattern, decoded, as they come (a subscriber on its own session)."""

    def __init__(self, bus, pattern: str) -> None:
        self.items: list[tuple[str, dict]] = []
        self._lock = threading.Lock()
        self.subscriber = bus.session.declare_subscriber(pattern, self._take)

    def _take(self, sample) -> None:
        with self._lock:
            self.items.append((str(sample.key_expr), codec.decode(sample.payload.to_bytes())))

    def on(self, key: str) -> list[dict]:
        with self._lock:
            return [m for k, m in self.items if k == key]


def serving(net, text: str) -> tuple[MapNode, Listen]:
    """The map node of ``text``, once it serves its info, and a listener to its outputs."""
    node = map_node(net, text)
    watch = net.bus("watch")
    outputs = Listen(watch, "sound/derived/**")
    wait_for(lambda: watch.query(keys.derived_info("sound"), timeout=0.5), what="the node")
    return node, outputs


def test_two_sources_an_expression_ranges_from_the_info_and_a_threshold(net, owner):
    fake = owner("pepper", model_info("pepper"))
    node = map_node(net, TEXT)
    watch = net.bus("watch")
    outputs, events = Listen(watch, "sound/derived/**"), Listen(watch, "sound/events/*")
    described = wait_for(lambda: watch.query(keys.derived_info("sound"), timeout=0.5), what="sound/info/derived")
    assert described[0]["derived"] == [{"name": "map/both", "key": "sound/derived/map/both", "unit": "%", "size": 1,
                                        "min": 0.0, "max": 100.0,
                                        "sources": ["pepper/joints/HeadYaw", "pepper/joints/HeadPitch"]}]
    assert described[0]["events"] == {"both": {"key": "sound/events/both", "on": 60.0, "off": 40.0}}
    low, high = HEAD_YAW["min"], HEAD_YAW["max"]
    sent: dict[float, float] = {}
    for i in range(60):
        yaw, pitch = low + (high - low) * (i % 30) / 29, 0.9
        t = time.time()
        fake.frame(t, pose(HeadYaw=yaw, HeadPitch=pitch))
        sent[t] = 100 * ((yaw - low) / (high - low)) * pitch  # a (its info's range) × b (from = [0, 1])
        time.sleep(0.01)
    got = wait_for(lambda: (lambda o: o if len(o) >= 30 else None)(outputs.on("sound/derived/map/both")),
                   what="the map's outputs")
    for message in got:
        assert math.isclose(message["v"], sent[message["t"]], rel_tol=1e-9, abs_tol=1e-9), message
    wait_for(lambda: len(events.on("sound/events/both")) >= 3, what="the threshold's events")
    states = [m["state"] for m in events.on("sound/events/both")]
    assert states[:3] == ["on", "off", "on"], states  # each crossing once: 0..90 % twice
    assert all(m["kind"] == "both" for m in events.on("sound/events/both"))
    assert node.stats["triggers"] >= 3


def test_a_silent_source_is_said_and_a_source_that_never_came_too(net, owner, caplog):
    fake = owner("pepper", model_info("pepper"))
    text = TEXT + '\n[nodes.sound.maps.ghost]\nsource = "pepper/joints/HedYaw"\n'
    caplog.set_level(logging.INFO, logger="sonibus")
    node = map_node(net, text)
    watch = net.bus("watch")
    events = Listen(watch, "sound/events/map")
    for _ in range(20):
        fake.frame(time.time(), pose(HeadYaw=0.1, HeadPitch=0.5))
        time.sleep(0.01)
    wait_for(lambda: node.stats["sent"] > 0, what="an output")
    wait_for(lambda: "source 'pepper/joints/HedYaw' sent nothing in 0.5 s" in caplog.text, what="the unseen source")
    wait_for(lambda: "map 'both': its sources (pepper/joints/HeadYaw, pepper/joints/HeadPitch) silent for 0.5 s; "
                     "its output stops at its last value (" in caplog.text, what="the silence, said")
    silent = wait_for(lambda: events.on("sound/events/map"), what="the silence's event")
    assert (silent[0]["map"], silent[0]["state"]) == ("both", "silent")
    stats = wait_for(lambda: [s for s in watch.query(keys.node_stats(node.bus.host, "sound"), timeout=0.5)
                              if "both" in s.get("metrics", {}).get("silent_maps", {})],
                     what="the silent map in the node's stats (on the bus)")
    assert stats[0]["metrics"]["outputs"]["both"] == node.chains["both"].value
    assert node.stats["silent"] == 1 and node.stats["unseen"] == 1
    fake.frame(time.time(), pose(HeadYaw=0.2, HeadPitch=0.5))
    wait_for(lambda: "map 'both': its sources send again" in caplog.text, what="the map back")
    assert "both" not in node.metrics()["silent_maps"]


def test_nan_and_huge_values_never_reach_the_output_and_an_event_is_an_impulse(net, owner):
    fake = owner("pepper", model_info("pepper"))
    text = '''[nodes.sound]
adapter = "map"
per_joint_keys = true
[nodes.sound.maps.head]
source = "pepper/joints/HeadYaw"
from = [-1, 1]
to = [0, 10]
[nodes.sound.maps.hit]
source = "pepper/events/motion"
to = [0, 127]
'''
    node, outputs = serving(net, text)
    for seq, value in enumerate((0.5, math.nan, math.inf, -math.inf, 1e300, -1e7, b"\xc1 not msgpack", 0.0)):
        fake.put("pepper/joints/HeadYaw", value if isinstance(value, bytes) else
                 {"t": time.time(), "seq": seq, "v": value})
        time.sleep(0.02)  # (at a robot's rate: faster, a sink's pacing skips all but the newest)
        fake.put("pepper/events/motion", {"t": time.time(), "kind": "motion", "chain": "RArm", "state": "onset",
                                                 "seq": seq})
    wait_for(lambda: len(outputs.on("sound/derived/map/head")) >= 2 and outputs.on("sound/derived/map/hit"),
             what="the finite values' outputs and the event's")
    assert [m["v"] for m in outputs.on("sound/derived/map/head")] == [7.5, 5.0]
    wait_for(lambda: len(outputs.on("sound/derived/map/hit")) >= 4, what="two events' impulses")
    hits = [m["v"] for m in outputs.on("sound/derived/map/hit")]
    assert hits[:4] == [127.0, 0.0, 127.0, 0.0], hits  # each event an impulse: 1, then 0 again
    assert node.stats["bad"] == 6 and node.state == "running"  # (the bus's gate: NaN, ±inf, beyond ±1e6, garbage)


def test_an_info_that_lies_about_a_derived_values_size_is_not_trusted_for_memory():
    """A derived info's ``size`` is any integer to its schema: a made-up 10⁶ (or 10⁹) is read as at most 64."""
    ranges = Ranges({"derived": [{"key": "pepper/derived/x/y", "size": 10**6, "min": 0, "max": 1,
                                  "axes": ["a"] * 10**6},
                                 {"key": "pepper/derived/h/R", "box": {"min": [0, "x", 0], "max": [1, 1, 1]}}]})
    assert len(ranges.derived["pepper/derived/x/y"]) == MAX_COMPONENTS == len(ranges.axes["pepper/derived/x/y"])
    assert ranges.of(keys.Key.parse("pepper/derived/h/R"), 1) is None  # (a bad bound: no range, not a shift)
    assert ranges.of(keys.Key.parse("pepper/derived/h/R"), 2) == (0.0, 1.0)


def test_a_value_of_several_numbers_needs_its_axis_named(net, owner, caplog):
    fake = owner("pepper", model_info("pepper"))
    text = '''[nodes.sound]
adapter = "map"
[nodes.sound.maps.whole]
source = "pepper/derived/hand/R"
from = [0, 1]
[nodes.sound.maps.w]
source = "pepper/derived/hand/R.w"
from = [0, 1]
[nodes.sound.maps.z]
source = "pepper/derived/hand/R.z"
from = [0, 1]
'''
    node, outputs = serving(net, text)
    for seq in range(5):
        fake.put("pepper/derived/hand/R", {"t": time.time(), "seq": seq, "v": [0.1, 0.2, 0.25]})
        time.sleep(0.02)
    wait_for(lambda: outputs.on("sound/derived/map/z"), what="the z map's output")
    assert outputs.on("sound/derived/map/z")[0]["v"] == 0.25
    assert not outputs.on("sound/derived/map/whole") and not outputs.on("sound/derived/map/w")
    assert node.stats["bad_source"] >= 2
    assert "map 'whole': 'pepper/derived/hand/R' has 3 values: name one, as pepper/derived/hand/R.0" in caplog.text


def test_a_source_nobody_gives_a_range_waits_and_is_said_with_the_fix(net, owner, caplog):
    fake = owner("pepper", model_info("pepper"))
    node = map_node(net, '[nodes.sound]\nadapter = "map"\nunseen_s = 0.5\n[nodes.sound.maps.mine]\n'
                         'source = "pepper/derived/script/level"\n')
    deadline = time.monotonic() + 5
    while "no range yet for 'pepper/derived/script/level'" not in caplog.text:
        assert time.monotonic() < deadline, caplog.text
        fake.put("pepper/derived/script/level", {"t": time.time(), "seq": 1, "v": 0.5})
        time.sleep(0.05)
    assert "or give the map one: from = [LOW, HIGH]" in caplog.text
    assert node.stats["waiting_info"] > 0 and node.stats["sent"] == 0
