"""The maps file of the libmapper node (``adapters/libmapper/saved.py``): written whole,
read strictly; a file that cannot be read stops the node in one line and is left as it is."""

from __future__ import annotations

import pytest

from sonibus.adapters.libmapper.saved import MapFile, SavedMap

from ..conftest import run_cli

INSTALLATION = """[bus]
multicast = false

[nodes.mapper]
adapter = "libmapper"
interface = "lo"
maps = "kept/maps.json"
"""


def test_maps_are_written_whole_and_read_back(tmp_path):
    file = MapFile(tmp_path / "kept" / "maps.json")
    assert file.load() == []  # (no file yet: no maps)
    maps = [SavedMap(("listener/yaw",), "pepper/cmd/joints/set/HeadYaw", "y=x$0*2"),
            SavedMap(("pepper/joints/HeadYaw", "pepper/joints/HeadPitch"), "synth/cutoff", "y=x$0+x$1", True)]
    file.save(maps)
    assert file.load() == maps
    assert [p.name for p in file.path.parent.iterdir()] == ["maps.json"]  # (no temporary file left)


@pytest.mark.parametrize(("text", "said"), [
    ('{"maps": [', "not valid JSON"),
    ('[]', 'no "maps" list'),
    ('{"maps": [{"sources": [], "destination": "synth/cutoff"}]}', "map 1: sources must be a list of 1..8"),
    ('{"maps": [{"sources": ["nodevice"], "destination": "synth/cutoff"}]}', "map 1: 'nodevice' is not <device>/"),
    ('{"maps": [{"sources": ["a/b"], "destination": "synth/cutoff", "expression": 7}]}', "map 1: expression must"),
    ('{"maps": [{"sources": ["a/b"], "destination": "c/d", "muted": "no"}]}', "map 1: muted must be true or false"),
    ('{"maps": [{"sources": ["a/b"], "destination": "c/d"}, 5]}', "map 2: a map must be an object"),
])
def test_a_maps_file_that_cannot_be_read_is_refused_naming_what_is_wrong(tmp_path, text, said):
    path = tmp_path / "maps.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=f"^{path}: .*{said[:30]}"):
        MapFile(path).load()


def test_the_node_does_not_start_on_a_maps_file_it_cannot_read_and_leaves_the_file_as_it_is(tmp_path):
    (tmp_path / "show.toml").write_text(INSTALLATION)
    (tmp_path / "kept").mkdir()
    kept = tmp_path / "kept" / "maps.json"
    kept.write_text('{"maps": [{"sources": ["listener/yaw"], "destination": "pepper/cmd/joints/set/HeadYaw"')
    done = run_cli("run", str(tmp_path / "show.toml"))
    errors = [line for line in done.stderr.splitlines() if line.startswith("sonibus: error:")]
    assert done.returncode == 2 and len(errors) == 1, done.stderr
    assert errors[0].startswith(f"sonibus: error: {tmp_path / 'show.toml'} [nodes.mapper] line 7: key 'maps': "
                                f"{kept}: not valid JSON"), errors
    assert errors[0].endswith("— fix it or move it away")
    assert kept.read_text().endswith('"pepper/cmd/joints/set/HeadYaw"')  # untouched


def test_an_interface_this_machine_does_not_have_is_refused_before_libmapper_starts(tmp_path):
    (tmp_path / "show.toml").write_text(INSTALLATION.replace('interface = "lo"', 'interface = "eth9x"'))
    done = run_cli("run", str(tmp_path / "show.toml"))
    errors = [line for line in done.stderr.splitlines() if line.startswith("sonibus: error:")]
    assert done.returncode == 2 and len(errors) == 1, done.stderr
    assert "line 6: key 'interface': no interface 'eth9x' on this machine — interfaces: lo" in errors[0], errors
