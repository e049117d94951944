"""What a rogue participant sends besides data (issue 26): liveliness claims of robots
(``sonibus/robots/<robot>/<since>/<host>/<node>``: malformed keys, times that make no
sense, claims of made-up robots) and nodes' stats (``sonibus/stats/<host>/<node>``:
valid ones of made-up nodes, huge, malformed), each family a Hypothesis strategy of
``Input``s as in ``families.py``; ``claim_flood`` and ``stats_flood`` are the issue's
thousands at once.

A claim is sent ``how = "token"``: the fuzzer declares it as a liveliness token and holds
it until ``Fuzzer.release`` (after each family). A claim of pepper at a time that makes
sense but earlier than its owner's is left out on purpose: without access control it
rightly takes the robot (docs/design.md, "A rogue on the bus"); the shipped access
control for public venues keeps it out (tests/net/test_public_venue.py).
"""

from __future__ import annotations

import math
import time
from typing import Any

from hypothesis import strategies as st

from sonibus.bus.ownership import BUS_EPOCH_MS

from .families import HOSTILE, MALFORMED, ROBOT, VALID, Input, pack

ROBOTS = "sonibus/robots"
STATS = "sonibus/stats"
BASE = ("received", "sent", "dropped", "stale", "bad", "errors")


def _now_ms() -> int:
    return int(time.time() * 1000)


@st.composite
def claims(draw: st.DrawFn) -> Input:
    """A claim key: of a made-up robot (valid), of pepper at a time that makes no sense
    (hostile: refused), or not a claim at all (malformed)."""
    how = draw(st.sampled_from(["made_up", "time_zero", "future", "before_bus", "digits", "chunks", "since",
                                "names"]))
    host, node = draw(st.sampled_from([("rogue", "x"), ("laptop", "sim"), ("h" * 200, "n")]))
    if how == "made_up":  # another robot: a claim like any, with no owner behind it
        return Input("claim", VALID, "token", f"{ROBOTS}/fake{draw(st.integers(0, 10**6))}/{_now_ms()}/{host}/{node}",
                     b"", note=how)
    if how in ("time_zero", "future", "before_bus", "digits"):
        if how == "future":
            since = str(_now_ms() + draw(st.sampled_from([60_000, 86_400_000, 10**14])))
        elif how == "before_bus":
            since = str(BUS_EPOCH_MS - draw(st.integers(1, 10**9)))
        else:  # (5,000 digits: Python's int() of it raises, in whichever thread reads it)
            since = "0" if how == "time_zero" else "9" * 5000
        return Input("claim", HOSTILE, "token", f"{ROBOTS}/{ROBOT}/{since}/{host}/{node}", b"", note=how)
    if how == "chunks":
        key = draw(st.sampled_from([f"{ROBOTS}/{ROBOT}", f"{ROBOTS}/{ROBOT}/{_now_ms()}",
                                    f"{ROBOTS}/{ROBOT}/{_now_ms()}/a/b/c", f"{ROBOTS}/{ROBOT}/{_now_ms()}/a"]))
    elif how == "since":
        key = f"{ROBOTS}/{ROBOT}/{draw(st.sampled_from(['abc', '-5', '1e12', '١٢٣', '0x10', '']))}/{host}/{node}"
    else:  # names no node could have: a token's key may hold them
        name = draw(st.sampled_from(["ç", "a" * 300, "x y", "tab\there", "%%", "@"]))
        key = f"{ROBOTS}/{ROBOT}/{_now_ms()}/{name}/{node}"
    return Input("claim", MALFORMED, "token", key, b"", note=how)


def claim_flood(count: int = 3000) -> list[Input]:
    """The issue's made-up robots whose names sort before pepper, claimed together."""
    since = _now_ms()
    return [Input("claim", HOSTILE, "token", f"{ROBOTS}/a{i:04d}/{since}/rogue/x", b"", note="flood of robots")
            for i in range(count)]


def node_stats(host: str, node: str, counters: int = 6) -> dict[str, Any]:
    """A valid ``node_stats`` message with ``counters`` counters (256, the most: about 16 KB)."""
    counted = {name: 0 for name in BASE} | {f"a_counter_made_up_on_the_bus_{i:04d}": i
                                            for i in range(max(0, counters - len(BASE)))}
    return {"t": time.time(), "host": host, "node": node, "adapter": "fake", "state": "running", "uptime_s": 1.0,
            "interval_s": 1.0, "counters": counted, "rates": {k: 0.0 for k in counted},
            "process": {"pid": 1, "cpu_percent": 0.0, "rss_bytes": 1}}


@st.composite
def stats(draw: st.DrawFn) -> Input:
    """Nodes' stats: valid ones of made-up nodes (some of 16 KB), or huge, or malformed."""
    host, node = f"host{draw(st.integers(0, 10**6))}", draw(st.sampled_from(["web", "sound", "n" * 64]))
    key = f"{STATS}/{host}/{node}"
    how = draw(st.sampled_from(["valid", "big", "huge", "many", "garbage", "missing", "nan", "negative", "types",
                                "key"]))
    message: Any = node_stats(host, node, 256 if how == "big" else 6)
    if how in ("valid", "big"):
        return Input("stats", VALID, "put", key, pack(message), note=how)
    if how == "huge":
        message["counters"].update({f"c{i:05d}": i for i in range(6000)})  # (over 64 KiB)
    elif how == "many":
        message["rates"].update({f"r{i:03d}": 0.0 for i in range(300)})  # (past the schema's 256)
    elif how == "garbage":
        return Input("stats", MALFORMED, "put", key, b"\xc1" + draw(st.binary(max_size=32)), note=how)
    elif how == "missing":
        del message[draw(st.sampled_from(["counters", "rates", "process", "host", "t"]))]
    elif how == "nan":
        message["rates"]["received"] = draw(st.sampled_from([math.nan, math.inf]))
    elif how == "negative":
        message["counters"]["dropped"] = -1
    elif how == "types":
        message[draw(st.sampled_from(["counters", "uptime_s", "state", "process"]))] = draw(
            st.sampled_from([None, "x", [1, 2], {"a": "b"}, b"\x00"]))
    else:
        key = draw(st.sampled_from([f"{STATS}/{host}", f"{STATS}/{host}/{node}/extra", STATS]))
    return Input("stats", HOSTILE if how in ("huge", "many") else MALFORMED, "put", key, pack(message), note=how)


def stats_flood(count: int = 3000) -> list[Input]:
    """The issue's made-up nodes, each a valid ~16 KB stats message, all at once."""
    return [Input("stats", VALID, "put", f"{STATS}/flood{i}/node{i}", pack(node_stats(f"flood{i}", f"node{i}", 256)),
                  note="flood of nodes") for i in range(count)]


ROGUE_FAMILIES = {"claim": claims, "stats": stats}
