"""Tables keyed by names from the network stay small in bytes, not only in count
(``bus/capped.py``): one frame's 128 joint names may fill its 64 KB payload, and the
tables worked out per joint list or key (a node's gate and selection, its pacing, an OSC
target's addresses and plans) held up to 1,024 or 10,000 of them — 107 MB in one sink's
selection for 1,024 made-up joint lists, 241 kB per frame of one 60,000-character name."""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from sonibus.adapters.osc.config import Target
from sonibus.adapters.osc.profiles import SonibusProfile
from sonibus.bus import framing
from sonibus.bus.capped import Capped
from sonibus.bus.codec import encode
from sonibus.bus.keys import Key
from sonibus.bus.pacing import Spacing
from sonibus.bus.streams import Selection

BOUND = 16e6  # bytes a table set may hold, whatever names come


@contextmanager
def held() -> Iterator[Callable[[], int]]:
    """The bytes allocated since, and still alive (tracemalloc)."""
    tracemalloc.start()
    try:
        yield lambda: tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()


def made_up_frame(robot: int, joints: int, length: int) -> bytes:
    names = [f"r{robot}j{j}".ljust(length, "x") for j in range(joints)]
    return encode(framing.frame(1.5, 7, names, [0.1] * joints))


def test_a_selection_keeps_few_bytes_of_made_up_joint_lists():
    payloads = [made_up_frame(i, 128, 400) for i in range(300)]  # (each near the 64 KB limit)
    with held() as now:
        selection = Selection(["*/joints/*"])
        for i, payload in enumerate(payloads):
            selection.incoming(f"r{i}/frame", payload)
        assert now() < BOUND, f"{now() / 1e6:.0f} MB held by one selection and its gate"


def test_a_selection_keeps_few_bytes_of_long_made_up_names():
    payloads = [encode(framing.frame(1.5, 7, [f"N{i}".ljust(60_000, "x")], [0.1])) for i in range(400)]
    with held() as now:
        selection = Selection(["*/joints/*"])
        for payload in payloads:
            selection.incoming("r/frame", payload)
        assert now() < BOUND, f"{now() / 1e6:.0f} MB held by one selection and its gate"


def test_a_robots_joint_list_is_still_worked_out_once():
    selection, names = Selection(["pepper/joints/*"]), ["HeadYaw", "HeadPitch"]
    first = selection.selected("pepper", names)
    for i in range(3000):  # (other robots' lists in between: the caps clear the tables now and then)
        selection.selected(f"r{i}", [f"J{i}", "HeadYaw"])
    assert selection.selected("pepper", names) is selection.selected("pepper", list(names))
    assert [s.key for s in selection.selected("pepper", names).sources] == [s.key for s in first.sources]


def test_pacing_keeps_few_bytes_of_long_made_up_keys():
    with held() as now:
        spacing = Spacing()
        for i in range(2000):  # (each key a new string, as each comes from the network)
            spacing.turn(f"r/joints/{i}".ljust(30_000, "x"), 1.0, 1, now=1.0)
        assert now() < BOUND, f"{now() / 1e6:.0f} MB held by the pacing of one sink"


def test_an_osc_target_keeps_few_bytes_of_addresses():
    with held() as now:
        profile = SonibusProfile(Target(to="127.0.0.1:9"))
        for i in range(2000):
            profile.address(Key.parse(f"r/joints/{i}".ljust(20_000, "x")))
        assert now() < BOUND, f"{now() / 1e6:.0f} MB held by one target's addresses"


def test_capped_starts_over_past_either_cap():
    table: Capped[str, int] = Capped(items=3, size=100)
    for key in "abc":
        table.put(key, 1, 10)
    table.put("d", 1, 10)  # a 4th entry: over the count
    assert list(table) == ["d"] and table.held == 10
    table.put("e", 1, 85)  # 95 bytes: kept
    table.put("f", 1, 10)  # 105: over the size
    assert list(table) == ["f"] and table.held == 10
    table.put("g", 1, 101)  # bigger than the table: not kept
    assert "g" not in table
