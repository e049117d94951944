"""A map that does not parse is refused when its file is loaded, in one line with the
file, the line and the key; the limits (sources, points, maps) are refused with their
number."""

from __future__ import annotations

import importlib.util
import re

import pytest

from sonibus.adapters.hear import Hear
from sonibus.adapters.map import MapNode
from sonibus.bus import ConfigError, config, runner

from .conftest import ROOT

HEAD = '''[bus]
multicast = false

[nodes.sound]
adapter = "map"
silent_s = 2

[nodes.sound.maps.cutoff]
source = "pepper/derived/hand/R.z"
to = [200, 2000]
'''


def refused(extra: str, head: str = HEAD) -> str:
    with pytest.raises(ConfigError) as caught:
        config.parse(head + extra, "shows/museum.toml").nodes["sound"].build(MapNode)
    return str(caught.value)


@pytest.mark.parametrize("extra, line, key, fragment", [
    ('curve = "expo"\n', 11, "maps.cutoff.curve", "'expo' is not a curve — curves: linear, exp, log, s, points"),
    ("smoth_ms = 80\n", 11, "maps.cutoff.smoth_ms", "unknown step 'smoth_ms' — steps: source, sources, expr"),
    ('curve = "exp"\nbase = 1\n', 12, "maps.cutoff.base", "1 must be more than 0 and not 1"),
    ("points = [[0, 0], [0.5, 1], [0.4, 1]]\n", 11, "maps.cutoff.points", "point 2 [0.4, 1]: x must increase"),
    ('expr = "x + y"\n', 11, "maps.cutoff.expr", "names 'y', which is no source of this map — sources: x"),
    ('expr = "__import__(\'os\').system(\'true\')"\n', 11, "maps.cutoff.expr", "calls something that is not one"),
    ('expr = "x.real"\n', 11, "maps.cutoff.expr", "uses attributes"),
    ("threshold = [500, 800]\n", 11, "maps.cutoff.threshold", "off below on"),
    ("clip = [100, 900]\n", 11, "maps.cutoff.clip", "within to = [200, 2000]"),
    ("smooth_ms = -5\n", 11, "maps.cutoff.smooth_ms", "-5 must be 0 (off) or more"),
    ("one_euro = {min_cutoff = 0}\n", 11, "maps.cutoff.one_euro", "must be more than 0"),
    ("one_euro = {cutoff = 1}\n", 11, "maps.cutoff.one_euro", "unknown key 'cutoff'"),
    ('unit = 3\n', 11, "maps.cutoff.unit", "3 is not a string"),
])
def test_a_bad_step_is_refused_with_file_line_and_key(extra, line, key, fragment):
    message = refused(extra)
    assert message.startswith(f"shows/museum.toml [nodes.sound] line {line}: key '{key}': "), message
    assert fragment in message, message


@pytest.mark.parametrize("table, line, key, fragment", [
    ('source = "pepper/cmd/say"\n', 9, "maps.bad.source", "is not a joint, derived value or event key"),
    ('source = "pepper/joints/Head Yaw"\n', 9, "maps.bad.source", "is not a key: it holds a space"),
    ('source = "pepper/joints//x"\n', 9, "maps.bad.source", "not a valid key expression"),
    ('sources = {a = "pepper/joints/HeadYaw", b = "nao/joints/HeadYaw"}\n', 8, "maps.bad.expr",
     "missing: how to combine a, b"),
    ('to = [0, 1]\n', 8, "maps.bad.source", "give source = \"KEY\" or sources"),
    ('source = "pepper/joints/HeadYaw"\nto = [3, 3]\n', 10, "maps.bad.to", "[3, 3] is no range"),
    ('source = "pepper/joints/HeadYaw"\nfrom = {y = [0, 1]}\n', 10, "maps.bad.from", "'y' is no source"),
])
def test_a_bad_map_is_refused_with_file_line_and_key(table, line, key, fragment):
    head = HEAD.replace('[nodes.sound.maps.cutoff]\nsource = "pepper/derived/hand/R.z"\nto = [200, 2000]\n',
                        "[nodes.sound.maps.bad]\n")
    message = refused(table, head)
    assert message.startswith(f"shows/museum.toml [nodes.sound] line {line}: key '{key}': "), message
    assert fragment in message, message


def test_200_sources_and_a_10000_point_curve_are_refused_with_their_limits():
    sources = ", ".join(f'j{i} = "pepper/joints/J{i}"' for i in range(200))
    message = refused("", HEAD.replace('source = "pepper/derived/hand/R.z"', f"sources = {{{sources}}}"))
    assert "line 9: key 'maps.cutoff.sources': 200 sources, at most 64 in one map" in message, message[:300]
    points = ", ".join(f"[{i / 10000}, 0.5]" for i in range(10000))
    message = refused(f'curve = "points"\npoints = [{points}]\n')
    assert "line 12: key 'maps.cutoff.points': 10000 points, at most 1000" in message, message[:300]
    maps = "".join(f'\n[nodes.sound.maps.m{i}]\nsource = "pepper/joints/HeadYaw"\n' for i in range(300))
    message = refused(maps)
    assert "line 8: key 'maps': 301 maps, at most 256 in one node" in message, message[:300]


def test_64_sources_and_1000_points_are_taken():
    sources = ", ".join(f'j{i} = "pepper/joints/J{i}"' for i in range(64))
    points = ", ".join(f"[{i / 1000}, 0.5]" for i in range(1000))
    text = HEAD.replace('source = "pepper/derived/hand/R.z"', f'sources = {{{sources}}}\nexpr = "max(j0, j63)"')
    node = config.parse(text + f"points = [{points}]\n", "ok.toml").nodes["sound"].build(MapNode)
    spec = node.config.specs[0]
    assert len(spec.sources) == 64 and len(spec.curve.points) == 1000


def test_the_docs_example_builds_with_the_hand_height_as_its_source():
    text = HEAD + 'unit = "Hz"\ncurve = "exp"\nsmooth_ms = 80\n'
    spec = config.parse(text, "ok.toml").nodes["sound"].build(MapNode).config.specs[0]
    assert (spec.sources[0].pattern, spec.sources[0].axis, spec.to, spec.unit) == \
        ("pepper/derived/hand/R", "z", (200.0, 2000.0), "Hz")


def test_every_toml_example_of_docs_mapping_md_builds():
    text = (ROOT / "docs" / "mapping.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```toml\n(.*?)```", text, re.S)
    assert len(blocks) >= 3
    for block in blocks:
        if "adapter = " not in block:  # (a map shown alone: in the cutoff example's node)
            block = '[nodes.sound]\nadapter = "map"\n' + block
        adapters = runner.build(config.parse(block, "docs/mapping.md"))
        assert any(isinstance(a, MapNode | Hear) for a in adapters), block  # (the hear node: its own block)


def test_the_curves_picture_of_the_docs_is_what_the_curves_draw():
    spec = importlib.util.spec_from_file_location("mapping_curves", ROOT / "scripts" / "mapping_curves.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert (ROOT / "docs" / "img" / "mapping-curves.svg").read_text(encoding="utf-8") == script.svg(), \
        "docs/img/mapping-curves.svg is stale: .venv/bin/python scripts/mapping_curves.py"
    assert "](img/mapping-curves.svg)" in (ROOT / "docs" / "mapping.md").read_text(encoding="utf-8")


def test_a_map_called_map_is_refused_and_a_disabled_map_is_listened_to_so_an_edit_can_enable_it():
    message = refused("", HEAD.replace("[nodes.sound.maps.cutoff]", "[nodes.sound.maps.map]"))
    assert "line 8: key 'maps.map': 'map' is the name of the node's own events" in message, message
    text = HEAD + '\n[nodes.sound.maps.off]\nsource = "nao/joints/HeadYaw"\nenabled = false\n'
    node = config.parse(text, "ok.toml").nodes["sound"].build(MapNode)
    assert node.config.patterns == ("pepper/derived/hand/R", "nao/joints/HeadYaw")
