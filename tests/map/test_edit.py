"""Editing maps while they run (``<node>/maps/<verb>``): an edit changes the output from
the next frame on, an invalid one is refused with its reason and the map keeps running as
it was, learn sets a source's range, undo takes a change back, and save writes the maps
into the installation file with its comments, so a restart runs them as edited."""

from __future__ import annotations

import math
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.adapters.map import MapNode
from sonibus.adapters.map.config import STEPS
from sonibus.bus import config, keys, runner
from sonibus.bus.errors import CommandError

from ..conftest import run_cli, wait_for
from ..features.conftest import model_info
from .conftest import pose
from .test_node import Listen

FILE = '''# the museum's sound (a comment the save keeps)
[nodes.sound]
adapter = "map"

[nodes.sound.maps.yaw]   # the head turns a filter
source = "pepper/joints/HeadYaw"
from = [-1, 1]           # radians: the show's span, not the joint's
to = [0, 100]
points = [[0, 0], [0.5, 0.5], [1, 1]]

[nodes.sound.maps.quiet]
source = "pepper/joints/HeadPitch"
enabled = false
'''


def start(net, path: Path) -> MapNode:
    """The map node of the installation file at ``path``, built as ``sonibus run`` builds it."""
    node = next(a for a in runner.build(config.load(path)) if isinstance(a, MapNode))
    return net.start(node)


def ask(bus, verb: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
    answers = bus.query(keys.maps("sound", verb), args or {}, timeout=5.0)
    assert len(answers) == 1, answers
    return answers[0]


class Head:
    """Frames of pepper's head at a yaw a test sets, each one's output awaited."""

    def __init__(self, net, owner) -> None:
        self.fake = owner("pepper", model_info("pepper"))
        self.watch = net.bus("watch")
        self.outputs = Listen(self.watch, "sound/derived/map/*")

    def output(self, yaw: float, map_: str = "yaw") -> float:
        """The output of the first frame sent now, at ``yaw``: frames go out until one of them
        (by its own ``t``) comes back through the map."""
        sent: set[float] = set()
        key = f"sound/derived/map/{map_}"

        def back() -> float | None:
            t = time.time()
            sent.add(t)
            self.fake.frame(t, pose(HeadYaw=yaw))
            time.sleep(0.01)
            first = [m for m in self.outputs.on(key) if m["t"] in sent]
            return min(first, key=lambda m: m["t"])["v"] if first else None
        value = wait_for(lambda: back() is not None and back, what=f"an output of {key}")
        return value()  # type: ignore[no-any-return]


def first_output(head: Head, yaw: float, after: float) -> float:
    """The output of the first frame with ``t`` past ``after`` (sent at ``yaw``)."""
    key = "sound/derived/map/yaw"

    def back() -> list[float] | None:  # (a list: an output of 0.0 is one)
        head.fake.frame(time.time(), pose(HeadYaw=yaw))
        time.sleep(0.01)
        later = [m for m in head.outputs.on(key) if m["t"] > after]
        return [min(later, key=lambda m: m["t"])["v"]] if later else None
    return wait_for(back, what="an output after the edit")[0]


def running(net, owner, tmp_path: Path) -> tuple[Path, MapNode, Head]:
    """``FILE`` in a folder of its own, its map node started from it, and pepper's head with
    the yaw map's output at yaw 0 (x = 0.5 → 50) seen."""
    path = tmp_path / "show.toml"
    path.write_text(FILE, encoding="utf-8")
    node = start(net, path)
    head = Head(net, owner)
    wait_for(lambda: first_output(head, 0.0, 0.0) == 50.0, what="the map at yaw 0 (x = 0.5 → 50)")
    return path, node, head


def test_an_edited_curve_changes_the_output_from_the_next_frame_on(net, owner, tmp_path):
    _, _, head = running(net, owner, tmp_path)
    reply = ask(head.watch, "edit", {"map": "yaw", "set": {"points": [[0, 0], [0.5, 0.9], [1, 1]]}})
    answered = time.time()
    assert reply["ok"], reply
    assert reply["result"]["changed"] == ["points"]
    assert first_output(head, 0.0, answered) == 90.0  # the first frame after the reply: the new curve


def test_an_invalid_edit_is_refused_with_its_reason_and_the_map_runs_as_it_was(net, owner, tmp_path):
    _, _, head = running(net, owner, tmp_path)
    for args, reason in [
        ({"map": "yaw", "set": {"points": [[0, 0], [0.6, 0.9], [0.4, 1]]}},
         "map 'yaw': key 'maps.yaw.points': point 2 [0.4, 1]: x must increase (the one before has x = 0.6)"),
        ({"map": "yaw", "set": {"smoth_ms": 80}}, "key 'maps.yaw.smoth_ms': unknown step 'smoth_ms'"),
        ({"map": "yaw", "set": {"to": [5, 5]}}, "key 'maps.yaw.to': [5, 5] is no range"),
        ({"map": "yaw", "set": {"curve": "expo"}}, "'expo' is not a curve — curves: linear, exp, log, s, points"),
        ({"map": "yaw", "set": {"source": "nao/joints/HeadYaw"}},
         "source 'nao/joints/HeadYaw' is not among those this node listens to — save, then restart the run"),
        ({"map": "nope", "set": {"to": [0, 1]}}, "no map 'nope' in node 'sound' — maps: yaw, quiet"),
        ({"map": "yaw", "set": {"to": "loud"}}, "key 'maps.yaw.to': 'loud' is not [LOW, HIGH]"),
        ({"map": "yaw", "sett": {}}, "edit: arguments: Additional properties are not allowed ('sett' was unexpected)"),
    ]:
        reply = ask(head.watch, "edit", args)
        assert not reply["ok"] and reason in reply["error"]["message"], (args, reply)
        assert "\n" not in reply["error"]["message"]
    answered = time.time()
    assert first_output(head, 0.0, answered) == 50.0  # the last good version runs on
    table = ask(head.watch, "list")["result"]["maps"][0]["table"]
    assert table["points"] == [[0, 0], [0.5, 0.5], [1, 1]] and "smoth_ms" not in table


def test_enable_learn_and_undo(net, owner, tmp_path):
    _, _, head = running(net, owner, tmp_path)
    assert ask(head.watch, "edit", {"map": "quiet", "set": {"enabled": True, "from": [-1, 1]}})["ok"]
    wait_for(lambda: head.output(0.0, "quiet") is not None, what="the map enabled live")  # (pitch 0: the middle)
    reply = ask(head.watch, "learn", {"map": "yaw", "seconds": 0.3})
    assert reply["ok"] and reply["result"] == {"map": "yaw", "source": "x", "seconds": 0.3}, reply
    listed = ask(head.watch, "list")["result"]["maps"][0]
    assert listed["learning"]["source"] == "x"

    def learned() -> list | None:
        for yaw in (-0.5, 0.25, 0.5):
            head.fake.frame(time.time(), pose(HeadYaw=yaw))
            time.sleep(0.02)
        maps = ask(head.watch, "list")["result"]["maps"]
        return maps[0]["table"]["from"] if maps[0]["learning"] is None else None
    assert wait_for(learned, what="the learn's end") == [-0.5, 0.5]
    answered = time.time()
    assert first_output(head, 0.0, answered) == 50.0 and first_output(head, 0.25, time.time()) == 75.0
    undone = ask(head.watch, "undo", {"map": "yaw"})
    assert undone["ok"] and undone["result"]["table"]["from"] == [-1, 1], undone
    assert first_output(head, 0.5, time.time()) == 75.0  # from = [-1, 1] again: 0.5 rad is x = 0.75
    assert ask(head.watch, "undo", {"map": "yaw"})["error"]["message"] == \
        "undo: nothing to undo for map 'yaw' (the last 64 changes are kept)"


def test_save_keeps_the_comments_and_a_restart_runs_the_edited_maps(net, owner, tmp_path):
    path, node, head = running(net, owner, tmp_path)
    assert ask(head.watch, "edit", {"map": "yaw", "set": {"points": [[0, 0], [0.5, 0.9], [1, 1]],
                                                          "smooth_ms": 0}})["ok"]
    assert ask(head.watch, "edit", {"map": "yaw", "unset": ["smooth_ms"]})["ok"]
    reply = ask(head.watch, "save")
    assert reply["ok"] and reply["result"] == {"file": str(path.resolve()), "maps": ["quiet", "yaw"]}, reply
    text = path.read_text(encoding="utf-8")
    assert text == FILE.replace("points = [[0, 0], [0.5, 0.5], [1, 1]]", "points = [[0, 0], [0.5, 0.9], [1, 1]]")
    assert tomllib.loads(text)["nodes"]["sound"]["maps"]["yaw"]["points"][1] == [0.5, 0.9]
    node.stop()
    start(net, path)
    assert first_output(head, 0.0, time.time()) == 90.0


def test_sonibus_map_lists_the_maps_with_their_live_values(net, owner, tmp_path):
    _, _, head = running(net, owner, tmp_path)
    assert first_output(head, 0.5, time.time()) == 75.0  # (x = 0.75)
    # frames go on while the command starts and lists: the map must not fall silent (silent_s = 1 s),
    # which it did when a loaded machine took over a second to start the command
    done = threading.Event()

    def feed() -> None:
        while not done.wait(0.02):
            head.fake.frame(time.time(), pose(HeadYaw=0.5))
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        result = run_cli("map", "sound", "--count", "2", "--interval", "0.1", *net.cli_args())
    finally:
        done.set()
        feeder.join(5)
    assert result.returncode == 0, result.stderr
    views = result.stdout.split("\n\n")
    assert len(views) == 2, result.stdout
    assert views[0].splitlines() == [
        "sound/quiet  pepper/joints/HeadPitch  in     — ▕          ▏  out —   [0, 1] linear  DISABLED",
        "sound/yaw    pepper/joints/HeadYaw    in 0.750 ▕███████▌  ▏  out 75  [0, 100] points"]
    missing = run_cli("map", "nosuchnode", "--count", "1", "--timeout", "0.3", *net.cli_args())
    assert missing.returncode == 3 and "no map node answered on nosuchnode/maps/list" in missing.stderr, missing


def test_any_edit_is_taken_whole_or_refused_in_one_line_and_every_output_stays_in_range(net, tmp_path):
    """Hypothesis: random steps (known and unknown, values of every JSON type, NaN and
    infinities too) sent as edits; each is applied whole or refused in one line naming the
    map, and the map that runs after it gives finite outputs within its declared range."""
    path = tmp_path / "show.toml"
    path.write_text(FILE, encoding="utf-8")
    node = start(net, path)
    numbers = st.one_of(st.integers(-10**7, 10**7), st.floats(allow_nan=True, allow_infinity=True))
    value = st.recursive(st.one_of(numbers, st.booleans(), st.text(max_size=12), st.none()),
                         lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=4), inner,
                                                                                     max_size=3), max_leaves=12)
    steps = st.dictionaries(st.sampled_from([*STEPS, "smoth_ms", "x"]), value | st.lists(numbers, min_size=2,
                                                                                          max_size=2), max_size=4)
    taken = refused = 0

    @settings(max_examples=300, deadline=None, derandomize=True)
    @given(steps, st.lists(st.floats(-3, 3), min_size=1, max_size=5))
    def edit_then_run(given_steps: dict, raws: list) -> None:
        nonlocal taken, refused
        try:
            node.editor.edit("yaw", given_steps)
            taken += 1
        except CommandError as exc:
            refused += 1
            assert exc.message.startswith("map 'yaw': ") and "\n" not in exc.message, exc.message
        spec = node.editor.specs["yaw"]
        chain = node.chains.get("yaw")
        assert (chain is not None) == spec.enabled and (chain is None or chain.spec is spec)
        for i, raw in enumerate(raws):
            if chain is not None and chain.feed("x", raw, (-1.0, 1.0), float(i)):
                out = chain.compute(float(i))
                assert out is None or out.value is None or (math.isfinite(out.value)
                                                            and spec.low <= out.value <= spec.high), (spec, out)
    edit_then_run()
    assert taken > 10 and refused > 100, (taken, refused)
