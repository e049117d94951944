"""A rogue on the bus against the web page (issue 26): the page's STOP round trip with
3,000 made-up robots on the bus, the web node's memory and STOP under a flood of
made-up nodes' stats, and the replies a page gets of a burst of commands.

A simulated Pepper and a ``web`` node run in one process (``sonibus run``, the bus on
loopback TCP); this process is the page (aiohttp's WebSocket client, reading all the
time, as a browser does) and the rogue (a bus session of its own):

- STOP round trip: ``{"type": "stop"}`` until the reply naming pepper, alone on the bus,
  then with ``--fakes`` claims of robots whose names sort before pepper (no owner
  behind any: each is a liveliness token);
- stats flood: ``--nodes`` made-up node names on ``sonibus/stats/<host>/<node>``, each a
  valid message of about 16 KB, every second for ``--seconds``: the show process's RSS
  (from /proc) before and at its peak, the largest ``stats`` message the page got, and
  the STOP round trip meanwhile;
- replies: ``--burst`` valid commands (``behavior/list``) sent at once; the replies that
  came, those that said "dropped: too many at once", and those lost (none may be).

    .venv/bin/python bench/rogue.py [--fakes 3000] [--nodes 3000] [--seconds 15] [--burst 1000]

Writes bench/results/rogue.json and prints the figures.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import threading
import time
from pathlib import Path
from typing import Any

import aiohttp
from common import latency_stats, write
from web import web_show


def rss(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


class Page:
    """The operator's page: reads every message as it comes; ``ask`` waits for replies by id."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        self.ws = ws
        self.replies: dict[Any, list[dict[str, Any]]] = {}
        self.largest_stats = 0
        self.arrived = asyncio.Event()
        self.reader = asyncio.create_task(self._read())

    async def _read(self) -> None:
        async for message in self.ws:
            if message.type != aiohttp.WSMsgType.TEXT:
                continue
            if message.data.startswith('{"type": "stats"'):
                self.largest_stats = max(self.largest_stats, len(message.data))
                continue
            decoded = json.loads(message.data)
            if decoded.get("type") == "reply":
                self.replies.setdefault(decoded["id"], []).append(decoded)
                self.arrived.set()

    async def stop(self, id_: int) -> float:
        """Seconds from the stop sent to pepper's reply."""
        started = time.perf_counter()
        await self.ws.send_str(json.dumps({"type": "stop", "id": id_}))
        while not any(r.get("robot") == "pepper" for r in self.replies.get(id_, ())):
            self.arrived.clear()
            await asyncio.wait_for(self.arrived.wait(), 30)
        return time.perf_counter() - started

    async def stops(self, first: int, trials: int) -> list[float]:
        return [await self.stop(first + n) for n in range(trials)]


def node_stats(i: int) -> dict[str, Any]:
    counters = {name: 0 for name in ("received", "sent", "dropped", "stale", "bad", "errors")}
    counters.update({f"a_counter_made_up_on_the_bus_{k:04d}": k for k in range(250)})  # (the schema's most: 256)
    return {"t": time.time(), "host": f"host{i}", "node": f"node{i}", "adapter": "fake", "state": "running",
            "uptime_s": 1.0, "interval_s": 1.0, "counters": counters, "rates": {k: 0.0 for k in counters},
            "process": {"pid": 1, "cpu_percent": 0.0, "rss_bytes": 1}}


async def measure(url: str, bus: Any, show_pid: int, args: argparse.Namespace) -> dict[str, Any]:
    from sonibus.bus import encode, keys

    out: dict[str, Any] = {}
    async with aiohttp.ClientSession() as session, session.ws_connect(url, max_msg_size=0) as ws:
        page = Page(ws)
        await page.stops(0, 3)  # (warm up)
        out["stop_alone_s"] = await page.stops(100, args.trials)
        since = int(time.time() * 1000)
        tokens = [bus.token(f"{keys.ROBOTS}/a{i:04d}/{since}/rogue/x") for i in range(args.fakes)]
        await asyncio.sleep(3.0)  # every claim at the web node
        out["stop_with_fakes_s"] = await page.stops(1000, args.trials)
        for token in tokens:
            token.undeclare()

        payloads = [(keys.node_stats(f"host{i}", f"node{i}"), encode(node_stats(i))) for i in range(args.nodes)]
        out["stats_message_bytes"] = len(payloads[0][1])
        rss_before = rss(show_pid)
        flooding = threading.Event()
        peak = [rss_before]

        def flood() -> None:
            while not flooding.is_set():
                started = time.monotonic()
                for key, payload in payloads:
                    bus.session.put(key, payload)
                peak[0] = max(peak[0], rss(show_pid))
                flooding.wait(max(0.0, 1.0 - (time.monotonic() - started)))
        flooder = threading.Thread(target=flood, daemon=True)
        flooder.start()
        page.largest_stats = 0
        ends = time.monotonic() + args.seconds
        during: list[float] = []
        n = 2000
        while time.monotonic() < ends:
            during.append(await page.stop(n))
            n += 1
            peak[0] = max(peak[0], rss(show_pid))
            await asyncio.sleep(0.2)
        flooding.set()
        flooder.join(5)
        out.update(rss_before=rss_before, rss_peak=peak[0], stop_during_flood_s=during,
                   largest_stats_message=page.largest_stats)

        ids = list(range(10_000, 10_000 + args.burst))
        for id_ in ids:
            await ws.send_str(json.dumps({"type": "command", "id": id_, "robot": "pepper", "verb": "behavior/list"}))
        deadline = time.monotonic() + 30
        while sum(1 for i in ids if i in page.replies) < len(ids) and time.monotonic() < deadline:
            await asyncio.sleep(0.1)
        got = [page.replies[i][0] for i in ids if i in page.replies]
        out.update(burst=len(ids), replies=len(got), dropped_said=sum(1 for r in got if not r["ok"]),
                   lost=len(ids) - len(got))
        page.reader.cancel()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fakes", type=int, default=3000)
    parser.add_argument("--nodes", type=int, default=3000)
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--burst", type=int, default=1000)
    parser.add_argument("--trials", type=int, default=20)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    with web_show("bench-rogue") as (show, bus, url):
        time.sleep(2.0)  # pepper's info at the web node
        found = asyncio.run(measure(url, bus, show.pid, args))
    alone, fakes = latency_stats(found["stop_alone_s"]), latency_stats(found["stop_with_fakes_s"])
    flood = latency_stats(found["stop_during_flood_s"])
    result = {"machine": machine, **{k: v for k, v in vars(args).items()}, "stop_alone": alone,
              "stop_with_fakes": fakes, "stop_during_stats_flood": flood,
              **{k: found[k] for k in ("rss_before", "rss_peak", "largest_stats_message", "stats_message_bytes",
                                       "burst", "replies", "dropped_said", "lost")}}
    print(f"{'page STOP → pepper reply, ms':<44} {'p50':>7} {'p99':>7} {'max':>7}")
    for label, r in (("alone on the bus", alone), (f"with {args.fakes} made-up robots", fakes),
                     (f"during {args.nodes} made-up nodes' stats/s", flood)):
        print(f"{label:<44} {r['p50_us'] / 1000:>7.1f} {r['p99_us'] / 1000:>7.1f} {r['max_us'] / 1000:>7.1f}")
    print(f"web process RSS: {found['rss_before'] / 1e6:.0f} MB before the stats flood, "
          f"{found['rss_peak'] / 1e6:.0f} MB at its peak ({args.nodes} nodes × "
          f"{found['stats_message_bytes'] / 1e3:.0f} KB a second, {args.seconds:g} s); largest stats message to the "
          f"page {found['largest_stats_message'] / 1e3:.0f} KB")
    print(f"{args.burst} commands at once: {found['replies']} replies ({found['dropped_said']} 'dropped: too many "
          f"at once'), lost {found['lost']}")
    write("rogue", result)
    print(machine)


if __name__ == "__main__":
    main()
