"""What the map tests share: the cutoff example as docs/mapping.md gives it, a map node
built from an installation file's text, and a robot whose frames a test writes."""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sonibus.adapters.map import MapNode
from sonibus.bus import config

from ..features.conftest import FakeOwner, model_info, owner  # noqa: F401  (the owner fixture)
from ..midi.conftest import jack, jack_server, reader  # noqa: F401  (JACK and its MIDI ports: test_described)
from ..osc.conftest import receivers  # noqa: F401  (UDP receivers)
from ..oscquery.conftest import websocket  # noqa: F401  (a WebSocket client of OSCQuery)

ROOT = Path(__file__).resolve().parents[2]
PEPPER_JOINTS = [j["name"] for j in model_info("pepper")["joints"]]


def cutoff_example() -> str:
    """The first TOML block of docs/mapping.md: the cutoff example."""
    return re.search(r"```toml\n(.*?)```", (ROOT / "docs" / "mapping.md").read_text(encoding="utf-8"), re.S)[1]


def map_node(net, text: str, node: str = "sound", path: str = "show.toml", **options: Any) -> MapNode:
    """The map node ``node`` of the installation file ``text``, started on ``net``."""
    spec = config.parse(text, path).nodes[node]
    if options:
        spec = config.NodeSpec(spec.name, spec.adapter, {**spec.options, **options}, spec.where, spec.lines)
    return net.start(spec.build(MapNode))


def pose(**joints: float) -> dict[str, float]:
    """Every joint of Pepper at 0 but those given (the features node needs whole arms)."""
    return {**dict.fromkeys(PEPPER_JOINTS, 0.0), **joints}


def sweep(fake: FakeOwner, n: int = 0, rate_hz: float = 50.0, until: Callable[[], Any] | None = None,
          timeout: float = 10.0) -> None:
    """``n`` frames (or frames ``until`` it is true, within ``timeout``) at ``rate_hz`` with
    real times, the right arm swinging up and down."""
    deadline = time.monotonic() + timeout
    i = 0
    while i < n if until is None else not until():
        if time.monotonic() > deadline:
            raise AssertionError(f"frames for {timeout} s and still not {until}")
        fake.frame(time.time(), pose(RShoulderPitch=1.2 * math.sin(i / 8.0), RElbowRoll=0.5))
        time.sleep(1.0 / rate_hz)
        i += 1
