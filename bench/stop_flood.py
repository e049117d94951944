"""STOP whatever else is on the bus (issue 33, item 1): the time of a stop sent right after a
flood, on each path an operator stops from, beside a command's round trip on the data path.

A one-process show (``sonibus run``: a simulated Pepper at 100 frames/s, an OSC sink that
follows every frame and derived value, the web node) listens on loopback TCP. Each try
floods the show with 2,000 valid messages at 5,000/s, then sends one stop (the issue's
case: 0.3-0.9 s before the control session, ``bus/control.py``), on one path:

- bus query: ``send_command(stop)`` from this process's bus (its control session), until
  its reply is back;
- page's STOP: ``{"type": "stop"}`` on the operator's WebSocket (aiohttp's client, as the
  page talks), until its reply is back (the web node's ``stop_all`` from the show's
  control session);
- page's STOP, own process: the same from a web node in a ``sonibus run`` of its own that
  owns no robot, so opens no control session (``bus/runner.py``): its stop leaves from its
  data session and reaches the owner's control session over the link that one dialled;
- top's ``s y``: what top runs once ``y`` is typed, ``stop_all`` from a process with its
  control session (as ``sonibus top`` joins), until every robot answered.

Conditions: alone (no flood), frames (``nao/frame``) or derived values
(``pepper/derived/flood/x``), sent on the same link as the stop (this process's data
session) or on another (a flooding process of its own). Baseline, same try: the round trip
of ``behavior/list`` on the data path right after (what the flood does to a command that is
not a stop). Goal: p99 ≤ 50 ms on every path and condition.

    .venv/bin/python bench/stop_flood.py [--tries 20] [--flood 2000] [--rate 5000] [--name stop_flood]

``make bench`` also runs it with 5,000 messages as fast as one process sends them
(``stop_flood_heavy``): there a command on the data path waits behind the flood (behavior/list
271 ms p50 on the same link, 2 cores), as stop did before.

Writes bench/results/stop_flood.json and prints a table.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from common import free_port, latency_stats, write
from sink_throughput import SONIBUS, stop_process
from web import SHOW as WEB_SHOW

SHOW = WEB_SHOW + """
[nodes.osc]
adapter = "osc"
subscribe = ["*/frame", "*/joints/*", "*/derived/**"]
targets = ["127.0.0.1:9"]
"""  # web.py's show (pepper at 100 frames/s, the web node) and a sink that follows all the flood
WEB_ONLY = """[bus]
multicast = false

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{port}"
"""  # a page served by a process that owns no robot
KEYS = {"frames": "nao/frame", "derived": "pepper/derived/flood/x"}
PATHS = ("bus query", "page's STOP", "page's STOP, own process", "top's s y")
CONDITIONS = ("alone", "frames, same link", "frames, other link", "derived, same link", "derived, other link")
JOINTS = [f"J{i}" for i in range(20)]


def flood(publishers: dict[str, Any], kind: str, count: int, rate: float) -> None:
    """``count`` valid messages of ``kind`` at ``rate``/s, paced in bursts of 50."""
    from sonibus.bus import codec
    from sonibus.bus.framing import frame

    publisher, started = publishers[kind], time.perf_counter()
    for seq in range(count):
        message = (frame(time.time(), seq, JOINTS, [0.001 * seq] * len(JOINTS)) if kind == "frames"
                   else {"t": time.time(), "seq": seq, "v": [0.001 * seq] * 8})
        publisher.put(codec.encode(message))
        if seq % 50 == 49:
            time.sleep(max(0.0, started + (seq + 1) / rate - time.perf_counter()))


def flooder(endpoint: str, count: int, rate: float) -> None:
    """The other link: a process of its own that floods each time it reads a kind on stdin."""
    from sonibus.bus import BusConfig, open_session

    session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    try:
        publishers = {kind: session.declare_publisher(key) for kind, key in KEYS.items()}
        print("ready", flush=True)
        for line in sys.stdin:
            flood(publishers, line.strip(), count, rate)
            print("done", flush=True)
    finally:
        session.close()


@contextlib.contextmanager
def show(endpoint: str) -> Iterator[tuple[Any, str, str]]:
    """The show in a ``sonibus run`` of its own, a page's web node in another, and this
    process's bus (with its control session) on it, once pepper answers: the ``Bus`` and
    the two pages' WebSocket URLs (the show's, the other process's)."""
    from sonibus.bus import Bus, BusConfig, open_session, robot_info
    from sonibus.bus.control import open_control

    port, web_port = free_port(), free_port()
    with tempfile.TemporaryDirectory() as folder, contextlib.ExitStack() as closing:
        config, web_only = Path(folder) / "show.toml", Path(folder) / "web.toml"
        config.write_text(SHOW.format(port=port))
        web_only.write_text(WEB_ONLY.format(port=web_port))
        process = subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--listen", endpoint],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                   start_new_session=True)
        closing.callback(stop_process, process)
        web = subprocess.Popen([SONIBUS, "run", str(web_only), "--no-multicast", "--connect", endpoint],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
        closing.callback(stop_process, web)
        cfg = BusConfig(multicast=False, connect=(endpoint,))
        session = closing.enter_context(contextlib.closing(open_session(cfg)))
        control = closing.enter_context(contextlib.closing(open_control(cfg, session)))
        bus = Bus(session, node="bench-stop", control=control)
        deadline = time.monotonic() + 30
        while robot_info(bus, "pepper", timeout=0.5) is None:
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the show did not come up: {process.stderr.read()[-1000:]}")
        while not answers(web_port):  # (the other page's process up, and serving)
            if web.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the page's own process did not come up: {web.stderr.read()[-1000:]}")
            time.sleep(0.1)
        yield bus, f"ws://127.0.0.1:{port}/ws", f"ws://127.0.0.1:{web_port}/ws"


def answers(port: int) -> bool:
    """Whether something accepts TCP connections on 127.0.0.1:``port``."""
    with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.5):
        return True
    return False


def stop_all_once(bus: Any) -> None:
    """``stop_all`` as top runs it, until every robot answered (or the query ended)."""
    from sonibus.bus.client import stop_all

    ended = threading.Event()
    stop_all(bus, lambda robot, outcome: ended.set() if robot == "pepper" else None,
             lambda robots, error: ended.set(), timeout=5.0)
    if not ended.wait(6.0):
        raise RuntimeError("stop_all: no answer within 6 s")


async def measure(bus: Any, urls: tuple[str, str], other: subprocess.Popen[str], tries: int, count: int,
                  rate: float) -> dict[str, dict[str, list[float]]]:
    import aiohttp

    from sonibus.bus import send_command

    publishers = {kind: bus.session.declare_publisher(key) for kind, key in KEYS.items()}
    times: dict[str, dict[str, list[float]]] = {c: {p: [] for p in (*PATHS, "baseline")} for c in CONDITIONS}
    async with aiohttp.ClientSession() as session, session.ws_connect(urls[0]) as show_ws, \
            session.ws_connect(urls[1]) as own_ws:
        ids = iter(range(1 << 30))

        async def page_stop(ws: Any) -> None:
            sent = next(ids)
            await ws.send_str(json.dumps({"type": "stop", "id": sent}))
            while True:
                answer = json.loads((await ws.receive(timeout=10)).data)
                if answer.get("type") == "reply" and answer["id"] == sent:
                    if "pepper" not in json.dumps(answer):
                        raise RuntimeError(f"the page's stop did not reach pepper: {answer}")
                    return

        def bus_stop() -> None:
            send_command(bus, "pepper", "stop", timeout=5.0)

        paths: dict[str, Callable[[], Any]] = {"bus query": lambda: asyncio.to_thread(bus_stop),
                                               "page's STOP": lambda: page_stop(show_ws),
                                               "page's STOP, own process": lambda: page_stop(own_ws),
                                               "top's s y": lambda: asyncio.to_thread(stop_all_once, bus)}
        for condition in CONDITIONS:
            kind, _, link = condition.partition(", ")
            for n in range(tries + 1):  # (the first warms up)
                for path, stop in paths.items():
                    if link == "same link":
                        await asyncio.to_thread(flood, publishers, kind, count, rate)
                    elif link == "other link":
                        assert other.stdin is not None and other.stdout is not None
                        other.stdin.write(kind + "\n")
                        other.stdin.flush()
                        await asyncio.to_thread(other.stdout.readline)
                    started = time.perf_counter()
                    await stop()
                    took = time.perf_counter() - started
                    started = time.perf_counter()
                    await asyncio.to_thread(send_command, bus, "pepper", "behavior/list", None, 5.0)
                    if n:
                        times[condition][path].append(took)
                        times[condition]["baseline"].append(time.perf_counter() - started)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=20)
    parser.add_argument("--flood", type=int, default=2000, help="messages per flood")
    parser.add_argument("--rate", type=float, default=5000.0, help="their rate, /s")
    parser.add_argument("--name", default="stop_flood", help="of the results file")
    parser.add_argument("--flooder", metavar="ENDPOINT", help=argparse.SUPPRESS)  # (the other link's process)
    args = parser.parse_args()
    if args.flooder:
        flooder(args.flooder, args.flood, args.rate)
        return
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with show(endpoint) as (bus, *urls):
        other = subprocess.Popen([sys.executable, __file__, "--flooder", endpoint, "--flood", str(args.flood),
                                  "--rate", str(args.rate)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 text=True, start_new_session=True)
        try:
            assert other.stdout is not None
            if other.stdout.readline().strip() != "ready":
                raise RuntimeError("the flooding process did not start")
            times = asyncio.run(measure(bus, (urls[0], urls[1]), other, args.tries, args.flood, args.rate))
        finally:
            if other.stdin is not None:
                other.stdin.close()  # (its loop ends: it closes its session)
            try:
                other.wait(5)
            except subprocess.TimeoutExpired:
                stop_process(other)
    rows = {c: {p: latency_stats(v) for p, v in paths.items()} for c, paths in times.items()}
    worst = max(rows[c][p]["p99_us"] for c in CONDITIONS for p in PATHS)
    result: dict[str, Any] = {"tries": args.tries, "flood": args.flood, "rate": args.rate, "machine": machine,
                              "stop": rows, "worst_p99_ms": worst / 1000}
    result["summary"] = [
        {"scenario": f"(issue 33) stop after {args.flood} msgs at {args.rate:g}/s, {c}: {p}, p50 / p99",
         "sonibus": f"{rows[c][p]['p50_us'] / 1000:.1f} / {rows[c][p]['p99_us'] / 1000:.1f} ms",
         "baseline": f"{rows[c]['baseline']['p50_us'] / 1000:.1f} / {rows[c]['baseline']['p99_us'] / 1000:.1f} ms "
                     "(behavior/list, data path)",
         "ratio": f"{rows[c][p]['p50_us'] / rows[c]['baseline']['p50_us']:.2f}× / "
                  f"{rows[c][p]['p99_us'] / rows[c]['baseline']['p99_us']:.2f}×",
         "goal": "p99 ≤ 50 ms", "met": "yes" if rows[c][p]["p99_us"] <= 50_000 else "no"}
        for c in CONDITIONS for p in PATHS]
    print(f"ms, {args.tries} tries, p50 / p99{'':<14}" + "".join(f"{p:>26}" for p in (*PATHS, "baseline")))
    for c in CONDITIONS:
        print(f"{c:<36}" + "".join(f"{rows[c][p]['p50_us'] / 1000:>16.1f} / {rows[c][p]['p99_us'] / 1000:>5.1f}  "
                                   for p in (*PATHS, "baseline")))
    print(f"goal: p99 ≤ 50 ms on every path — {'met' if worst <= 50_000 else 'not met'} (worst {worst / 1000:.1f} ms); "
          f"{machine}")
    write(args.name, result)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
