"""Issue 26, items 3 and 4, at the web node: a participant on the bus that makes up
robots (liveliness claims) or nodes (stats) neither delays the page's STOP nor grows
what the node keeps and sends every page each second."""

from __future__ import annotations

import json
import time

from sonibus import schemas
from sonibus.adapters import web as web_adapter
from sonibus.bus import encode, keys
from sonibus.bus.ownership import MAX_ROBOTS

from ..conftest import wait_for

FAKES = 2000


def fake_claims(bus, count: int = FAKES) -> list:
    """``count`` claims of robots ``a0000``… (they sort before pepper), no owner behind any."""
    since = int(time.time() * 1000)
    return [bus.token(f"{keys.ROBOTS}/a{i:04d}/{since}/rogue/x") for i in range(count)]


def test_the_pages_stop_is_one_query_whatever_the_robots_made_up(stage, websocket):
    """2,000 claims sorting before pepper delayed its STOP by 1.6 s (a stop per robot, one
    after another) and only about 250 of the 2,001 replies reached the page."""
    rogue = stage.net.bus("rogue")
    queries: list[str] = []  # (declared before the claims: the web node hears of it first)
    counting = rogue.serve("*/cmd/**", lambda query: queries.append(str(query.key_expr)))  # noqa: F841
    tokens = fake_claims(rogue)  # noqa: F841 (held)
    wait_for(lambda: len(stage.node._on_bus()) >= MAX_ROBOTS, 20, "the made-up robots at the web node",
             lambda: f"{len(stage.node._on_bus())} robots")
    page = websocket(stage.ws_url())
    page.wait("hello")
    page.send({"type": "stop", "id": "halt"})
    assert page.wait("reply", id="halt", robot="pepper")["ok"] is True
    silent = wait_for(lambda: [m for m in page.of("reply", id="halt") if "robots" in m], 10, "the silent robots")
    assert len(silent) == 1 and len(silent[0]["robots"]) == MAX_ROBOTS - 1
    assert "did not answer" in silent[0]["error"] and "a0000" in silent[0]["error"]
    assert queries == ["*/cmd/stop"], f"{len(queries)} stop queries, e.g. {queries[:2]}"
    assert len(page.of("reply", id="halt")) == 2
    assert stage.node.stats["capped"] > 0 and stage.node.state == "running"


def node_stats(host: str, node: str) -> dict:
    """A valid ``node_stats`` message of about 16 KB (as many counters as the schema allows, made up)."""
    counters = {name: 0 for name in ("received", "sent", "dropped", "stale", "bad", "errors")}
    counters.update({f"a_counter_made_up_on_the_bus_{i:04d}": i for i in range(250)})
    message = {"t": time.time(), "host": host, "node": node, "adapter": "fake", "state": "running", "uptime_s": 1.0,
               "interval_s": 1.0, "counters": counters, "rates": {k: 0.0 for k in counters},
               "process": {"pid": 1, "cpu_percent": 0.0, "rss_bytes": 1}}
    return message


def test_made_up_nodes_stats_do_not_grow_what_every_page_gets(stage, websocket, figure):
    """3,000 made-up nodes, each a valid ~16 KB stats message: every page got a 49 MB stats
    message a second, the web node grew from 80 to 422 MB, its STOP took 0.8 s."""
    page = websocket(stage.ws_url())
    page.wait("hello")
    wait_for(lambda: any({"sim-pepper", "web"} <= {n["node"] for n in m["nodes"]} for m in page.of("stats")), 10,
             "the show's own nodes at the page")
    rogue = stage.net.bus("rogue")
    count = 2 * web_adapter.MAX_NODES
    payloads = [(keys.node_stats(f"host{i}", f"node{i}"), node_stats(f"host{i}", f"node{i}")) for i in range(count)]
    schemas.validate("node_stats", payloads[0][1])  # (valid: what passes the gate)
    assert len(encode(payloads[0][1])) > 15_000
    for key, message in payloads:
        rogue.put(key, message)
    wait_for(lambda: stage.node.stats["capped"] > 0, 20, "the made-up nodes capped",
             lambda: repr(dict(stage.node.stats)))
    after = len(page.messages)
    stats = wait_for(lambda: [m for m in page.messages[after:] if isinstance(m, str) and '"type": "stats"' in m],
                     5, "a stats message after the flood")[0]
    nodes = json.loads(stats)["nodes"]
    figure(f"stats message with {count} made-up nodes of 16 KB", len(stats) / 1e3, f"KB ({len(nodes)} nodes)")
    assert len(nodes) <= web_adapter.MAX_NODES
    assert len(stats) < 1_000_000
    assert {"sim-pepper", "web"} <= {n["node"] for n in nodes}, "nodes listed before stay listed"
    made_up = next(n for n in nodes if n["node"].startswith("node"))
    assert len(made_up["counters"]) <= web_adapter.MAX_FIGURES and "metrics" not in made_up
    assert list(made_up["counters"])[:6] == ["received", "sent", "dropped", "stale", "bad", "errors"]
    page.send({"type": "stop", "id": 1})
    assert page.wait("reply", id=1, robot="pepper")["ok"] is True


def test_a_bad_stats_message_is_refused_with_its_reason_and_a_good_one_listed(stage, websocket, caplog):
    """Nodes' stats are checked once a second, each node's newest (issue 35: a wake-up a second,
    not one a node): one that is not a valid ``node_stats`` message is still refused, counted
    ``bad`` and warned about with the reason, its node not listed; a valid one is listed."""
    page = websocket(stage.ws_url())
    page.wait("hello")
    rogue = stage.net.bus("rogue")
    bad = {**node_stats("rogue-host", "liar"), "interval_s": "soon"}
    good = node_stats("rogue-host", "honest")
    bad_before = stage.node.stats["bad"]
    said = [0.0]

    def say() -> bool:  # (again every 0.6 s, as a node says its stats once a second, until refused: the
        if time.monotonic() - said[0] >= 0.6:  # rogue's session may not know the web node's subscription
            said[0] = time.monotonic()          # yet, and a put then reaches nobody)
            rogue.put(keys.node_stats("rogue-host", "liar"), bad)
            rogue.put(keys.node_stats("rogue-host", "honest"), good)
        return stage.node.stats["bad"] > bad_before

    wait_for(say, 10, "the bad stats refused", lambda: repr(dict(stage.node.stats)))
    # (counted, then warned about, on the node's thread: the warning may come just after the count)
    wait_for(lambda: any("sonibus/stats/rogue-host/liar' refused: not a valid node stats: interval_s"
                         in r.getMessage() for r in caplog.records), 5, "the refusal's warning",
             lambda: repr([r.getMessage() for r in caplog.records]))
    listed = wait_for(lambda: [m for m in page.of("stats") if "honest" in {n["node"] for n in m["nodes"]}], 5,
                      "the good stats at the page")[0]
    assert "liar" not in {n["node"] for n in listed["nodes"]}
