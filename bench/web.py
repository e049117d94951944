"""A web page's command round trip: a ``command`` sent on the operator's WebSocket until
its ``reply`` is back, beside the same command sent straight on the bus (issue 17).

A simulated Pepper and a ``web`` node run in one process (``sonibus run``, the bus on
loopback TCP); this process is both the page (aiohttp's WebSocket client, as a browser's
would talk) and, for the baseline, a bus session of its own. Each trial sends
``behavior/list`` (validated and answered, moves nothing) both ways, and ``stop`` from the
page (one reply per robot). The page's path adds the WebSocket, the node's loop, JSON and
one more bus hop.

    .venv/bin/python bench/web.py [--trials 500]

Writes bench/results/web.json and prints a table.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
from common import free_port, latency_stats, write
from sink_throughput import SONIBUS, stop_process

SHOW = """[bus]
multicast = false

[nodes.pepper]
adapter = "sim"
robot = "pepper"
rate_hz = 100

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{port}"
"""


async def page_trials(url: str, trials: int, bus: Any) -> dict[str, list[float]]:
    from sonibus.bus import send_command

    times: dict[str, list[float]] = {"page_list": [], "page_stop": [], "bus_list": []}
    async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
        ids = iter(range(1 << 30))

        async def ask(message: dict[str, Any]) -> float:
            message["id"] = next(ids)
            started = time.perf_counter()
            await ws.send_str(json.dumps(message))
            while True:
                answer = json.loads((await ws.receive(timeout=10)).data)
                if answer.get("type") == "reply" and answer["id"] == message["id"]:
                    if not answer["ok"]:
                        raise RuntimeError(f"refused: {answer['error']}")
                    return time.perf_counter() - started

        for n in range(trials + 3):  # (the first three warm up: sessions, routes, caches)
            page_list = await ask({"type": "command", "robot": "pepper", "verb": "behavior/list"})
            page_stop = await ask({"type": "stop"})
            started = time.perf_counter()
            await asyncio.to_thread(send_command, bus, "pepper", "behavior/list")
            bus_list = time.perf_counter() - started
            if n >= 3:
                for name, value in (("page_list", page_list), ("page_stop", page_stop), ("bus_list", bus_list)):
                    times[name].append(value)
    return times


@contextlib.contextmanager
def web_show(node: str) -> Iterator[tuple[subprocess.Popen[str], Any, str]]:
    """``SHOW`` in a ``sonibus run`` of its own on a loopback bus, and a bus session of this
    process (named ``node``) on it: the process, the ``Bus`` and the page's WebSocket URL,
    once pepper answers; everything ended on the way out."""
    from sonibus.bus import Bus, BusConfig, open_session, robot_info

    endpoint, port = f"tcp/127.0.0.1:{free_port()}", free_port()
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "show.toml"
        config.write_text(SHOW.format(port=port))
        show = subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--listen", endpoint],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
        session = None
        try:
            session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
            bus = Bus(session, node=node)
            deadline = time.monotonic() + 30
            while robot_info(bus, "pepper", timeout=0.5) is None:
                if show.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the show did not come up: {show.stderr.read()[-1000:]}")
            yield show, bus, f"ws://127.0.0.1:{port}/ws"
        finally:
            if session is not None:
                session.close()
            stop_process(show)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500)
    args = parser.parse_args()

    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    with web_show("bench-web") as (_, bus, url):
        times = asyncio.run(page_trials(url, args.trials, bus))
    rows = {name: latency_stats(values) for name, values in times.items()}
    page, stop, base = rows["page_list"], rows["page_stop"], rows["bus_list"]
    result = {"trials": args.trials, "machine": machine, "page_behavior_list_rtt": page, "page_stop_rtt": stop,
              "baseline_bus_behavior_list_rtt": base,
              "summary": [
                  {"scenario": "web page command → reply (behavior/list), p50 / p99",
                   "sonibus": f"{page['p50_us'] / 1000:.1f} / {page['p99_us'] / 1000:.1f} ms",
                   "baseline": f"{base['p50_us'] / 1000:.1f} / {base['p99_us'] / 1000:.1f} ms (on the bus)",
                   "ratio": f"{page['p50_us'] / base['p50_us']:.1f}× / {page['p99_us'] / base['p99_us']:.1f}×"},
                  {"scenario": "web page stop → reply, p50 / p99",
                   "sonibus": f"{stop['p50_us'] / 1000:.1f} / {stop['p99_us'] / 1000:.1f} ms", "baseline": ""}]}
    print(f"{'µs, ' + str(args.trials) + ' trials':<36} {'p50':>7} {'p99':>7} {'max':>7}")
    for label, r in (("behavior/list on the bus (base)", base), ("behavior/list from the page", page),
                     ("stop from the page", stop)):
        print(f"{label:<36} {r['p50_us']:>7.0f} {r['p99_us']:>7.0f} {r['max_us']:>7.0f}")
    write("web", result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
