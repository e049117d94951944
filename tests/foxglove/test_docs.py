"""docs/foxglove.md's example is a working installation file."""

from __future__ import annotations

import re
from pathlib import Path

from sonibus.adapters.foxglove.server import FoxgloveServer
from sonibus.adapters.recorder.recorder import Recorder
from sonibus.bus import config, runner

DOC = Path(__file__).resolve().parents[2] / "docs" / "foxglove.md"


def test_the_example_builds_a_foxglove_node_and_a_recorder_with_views(tmp_path, monkeypatch):
    text = re.search(r"```toml\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S).group(1)
    monkeypatch.chdir(tmp_path)  # (its recorder writes into the working folder)
    nodes = {type(node): node for node in runner.build(config.parse(text))}
    assert nodes[FoxgloveServer].config.listen == "127.0.0.1:8765"
    assert nodes[Recorder].config.foxglove is True
    assert all(node.state == "new" for node in nodes.values())
