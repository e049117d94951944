"""A full show, node by node (issue 27): what each node of an installation costs,
beside minimal harnesses of the same libraries, in the same run.

The show: a simulated Pepper at 50 frames/s (idle motion), and every other node
with a client attached — ``osc`` (joints, derived values and events to a UDP
receiver), ``osc-gateway`` (listening), ``features``, ``recorder`` (an MCAP file),
``web`` (a page's WebSocket, read), ``oscquery`` (a client LISTENing to every
joint), ``foxglove`` (a client subscribed to every channel) and ``midi`` (a
private JACK server, dummy driver). Two layouts, each round:

- one process (``sonibus run show.toml``, as one machine runs an installation):
  its CPU;
- a process per node (``--only NODE``, each connected to a ``sonibus router``): each
  node's CPU, its own Zenoh session included (the router's said apart). The sim's
  session sends each frame to every session that subscribes to it (seven nodes here),
  and so does its floor, a publisher.

Beside the nodes, at the same time (measured over the same window: one after the other,
a node's ratio to its floor moved by ±30 % from run to run on a VM whose speed drifts over
minutes), the floors: a zenoh-python publisher of the same frames at the same
rate (the sim's), each frame taken by as many sessions as take the sim's in the show
(``FRAME_TAKERS``: a publisher's send to each is its essential work, issue 35), a
subscriber of them with an empty callback (what any sink pays
to receive), and ``floor.py``'s minimal OSC sink, of the frames alone and of the
frames with a derived frame beside each (the OSC node's work in the show: it sends
the features node's derived values too). Each floor's process is given as many Zenoh
links as its node's holds, at the same lease (``bench/links.py``: a show's process links
with every other one and keeps each link alive, the bus's cost of membership that a floor
on a private pair of sessions did not pay; ``--private-floors``: as before). CPU is each process's, from
``/proc/<pid>/task/*/schedstat`` over the window after a warm-up; medians of rounds.

    .venv/bin/python bench/show.py [--rounds 2] [--seconds 8] [--name show]
    .venv/bin/python bench/show.py --lease-ms 10000 --name show_lease10s  # its nodes' (and floors') lease 10 s
    .venv/bin/python bench/show.py --private-floors --name show_private_floors  # floors without the nodes' links
    .venv/bin/python bench/show.py --nodes foxglove,oscquery  # those nodes and their floors only
    .venv/bin/python bench/show.py --nodes foxglove,oscquery --against DIR  # and DIR's beside them

``--nodes``: only the named nodes in a process each, with the sim and the features node that
feed them (measured too), beside their floors; no one-process layout (quicker, for one node's
before and after). With ``--against DIR`` too, the same nodes of the tree in DIR run beside
them on the same bus, fed the same frames, each with clients of its own, measured over the
same window: a change's before and after in the same conditions (a run's ratio to a floor
measured apart moves by ±15 % on a shared machine).

"Before" figures come from the same script run against an older tree:
``PYTHONPATH=<dir with sonibus/{bus,adapters,schemas} of that tree> .venv/bin/python
bench/show.py --name show_before`` (the ``sonibus`` processes import that tree).

Writes bench/results/<name>.json and prints a table.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import socket
import statistics
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
import node_floors
from common import free_port, write, zenoh_config
from floor import CONTEXT, Case, cpu_ns, floor_sink, publish, switches
from links import Links
from midi_rate import start_jack
from sink_throughput import SONIBUS, stop_process

RATE_HZ = 50
WARMUP_S = 3.0
SHOW_GOAL_PCT = 20.0  # issue 35: the whole show in one `sonibus run`, % of a core
NODE_GOAL = 1.5  # issue 35: each node in its own process, × its floor
FRAME_TAKERS = 7  # the show's nodes that take the robot's frames (all but the gateway): its publisher's fan-out
BUS_OPTIONS = ""  # more [bus] lines of the show, e.g. "\nlease_ms = 10000" (--lease-ms)
LINKED = True  # each floor with as many Zenoh links as its node (bench/links.py); --private-floors: False
FLOOR_OF = {"publisher": "sim", "subscriber": "gateway", "osc sink": "osc", "osc sink + derived": "osc",
            **{name: name for name in node_floors.NODES}}  # the node whose links a floor is given
NODES = ("sim", "osc", "gateway", "features", "recorder", "web", "oscquery", "foxglove", "midi")
SHOW = """[bus]
multicast = false{bus_options}

[nodes.sim]
adapter = "sim"
robot = "pepper"
rate_hz = {rate}
idle = true

[nodes.osc]
adapter = "osc"
subscribe = ["pepper/joints/*", "pepper/derived/**", "pepper/events/*"]
targets = ["127.0.0.1:{osc}"]

[nodes.gateway]
adapter = "osc-gateway"
listen = "127.0.0.1:{gateway}"

[nodes.features]
adapter = "features"
robots = "pepper"

[nodes.recorder]
adapter = "recorder"
path = "{folder}/show-{{time}}.mcap"
status_every_s = 0

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{web}"

[nodes.oscquery]
adapter = "oscquery"
listen = "127.0.0.1:{oscquery}"
gateway = "127.0.0.1:{gateway}"
mdns = false

[nodes.foxglove]
adapter = "foxglove"
listen = "127.0.0.1:{foxglove}"

[nodes.midi]
adapter = "midi"
api = "jack"
"""
JOINTS = ("HeadYaw", "HeadPitch", "HipRoll", "HipPitch", "KneePitch", "LShoulderPitch", "LShoulderRoll",
          "LElbowYaw", "LElbowRoll", "LWristYaw", "LHand", "RShoulderPitch", "RShoulderRoll", "RElbowYaw",
          "RElbowRoll", "RWristYaw", "RHand")


# -- clients ---------------------------------------------------------------------------------


async def _read(ws: aiohttp.ClientWebSocketResponse, counts: dict[str, int], name: str) -> None:
    async for message in ws:
        if message.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY):
            counts[name] = counts.get(name, 0) + 1


async def _clients(ports: dict[str, int], counts: dict[str, int], stop: asyncio.Event, ready: Any) -> None:
    """A page on the web node, an OSCQuery client LISTENing to every joint, a Foxglove client
    subscribed to every channel (each of those whose node has a port in ``ports``); each reads
    all it is sent until ``stop``."""
    async with aiohttp.ClientSession() as session:
        deadline = time.monotonic() + 30
        while True:
            try:
                web = await session.ws_connect(f"ws://127.0.0.1:{ports['web']}/ws") if "web" in ports else None
                oscquery = await session.ws_connect(f"ws://127.0.0.1:{ports['oscquery']}/") \
                    if "oscquery" in ports else None
                foxglove = await session.ws_connect(f"ws://127.0.0.1:{ports['foxglove']}",
                                                    protocols=("foxglove.sdk.v1", "foxglove.websocket.v1")) \
                    if "foxglove" in ports else None
                break
            except aiohttp.ClientError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.2)
        for joint in JOINTS if oscquery is not None else ():
            await oscquery.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": f"/pepper/joints/{joint}"}))
        subscribed: set[int] = set()

        async def foxglove_reader() -> None:
            async for message in foxglove:
                if message.type == aiohttp.WSMsgType.TEXT:
                    data = json.loads(message.data)
                    fresh = [c["id"] for c in data.get("channels", []) if c["id"] not in subscribed] \
                        if data.get("op") == "advertise" else []
                    if fresh:
                        subscribed.update(fresh)
                        await foxglove.send_str(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": channel, "channelId": channel} for channel in fresh]}))
                elif message.type == aiohttp.WSMsgType.BINARY:
                    counts["foxglove"] = counts.get("foxglove", 0) + 1

        tasks = [*([asyncio.create_task(_read(web, counts, "web"))] if web is not None else []),
                 *([asyncio.create_task(_read(oscquery, counts, "oscquery"))] if oscquery is not None else []),
                 *([asyncio.create_task(foxglove_reader())] if foxglove is not None else [])]
        ready.set()
        await stop.wait()
        for ws in (web, oscquery, foxglove):
            if ws is not None:
                await ws.close()
        for task in tasks:
            task.cancel()


def clients(ports: dict[str, int], counts: dict[str, int], ready: Any, done: Any) -> None:
    """The clients and a UDP receiver for the OSC node, in this process (not measured)."""
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", ports["osc"]))  # (always bound: the OSC node, if run, sends to it)
    receiver.settimeout(0.2)

    def drain() -> None:
        while not done.is_set():
            try:
                receiver.recv(65536)
                counts["osc"] = counts.get("osc", 0) + 1
            except TimeoutError:
                continue

    threading.Thread(target=drain, daemon=True).start()

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(_clients(ports, counts, stop, ready))
        await asyncio.wait([task, asyncio.create_task(asyncio.to_thread(done.wait))],
                           return_when=asyncio.FIRST_COMPLETED)
        if task.done():  # (the clients failed: said by the caller, which finds nothing received)
            task.result()
        stop.set()
        await task

    asyncio.run(main())
    receiver.close()


# -- the run ---------------------------------------------------------------------------------


def started(log: Path, process: subprocess.Popen[bytes], marker: str = "sonibus: running") -> None:
    deadline = time.monotonic() + 60
    while marker not in log.read_text(errors="replace"):
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{process.args}: did not start: {log.read_text(errors='replace')[-1500:]}")
        time.sleep(0.1)


def sonibus(config: Path, log: Path, *args: str, tree: str = "") -> subprocess.Popen[bytes]:
    """``sonibus run config``; ``tree``: a folder holding another tree's ``sonibus/`` (PYTHONPATH)."""
    env = {**os.environ, "PYTHONPATH": tree} if tree else None
    with open(log, "w") as out:
        return subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", *args], stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True, env=env)


def window(pids: dict[str, int], seconds: float) -> dict[str, float]:
    """CPU % of one core of each process over ``seconds``."""
    before, started_at = {name: cpu_ns(pid) for name, pid in pids.items()}, time.monotonic()
    time.sleep(seconds)
    wall = time.monotonic() - started_at
    return {name: 100.0 * (cpu_ns(pid) - before[name]) / 1e9 / wall for name, pid in pids.items()}


def measure_show(folder: Path, seconds: float, split: bool, tree: str = "",
                 waits: dict[str, float] | None = None, nodes: tuple[str, ...] = NODES,
                 against: str = "") -> dict[str, float]:
    """CPU % of ``show_running``'s processes over ``seconds`` after ``WARMUP_S``: ``{"show": cpu}``
    in one process, cpu by node in a process each; ``waits``: filled with each process's
    voluntary context switches a second over the same window."""
    with show_running(folder, split, tree, nodes, against) as pids:
        time.sleep(WARMUP_S)
        before = {name: switches(pid) for name, pid in pids.items()}
        cpu = window(pids, seconds)
        if waits is not None:
            waits.update({name: (switches(pid) - before[name]) / seconds for name, pid in pids.items()})
        return cpu


@contextlib.contextmanager
def show_running(folder: Path, split: bool, tree: str = "", nodes: tuple[str, ...] = NODES,
                 against: str = "", served: set[int] | None = None) -> Iterator[dict[str, int]]:
    """The show in one process (``"show"``) or in a process per node, clients attached, each fed;
    their process ids by name (not warmed up); stopped on leaving. ``tree``: the one process on
    another tree (see ``sonibus``); ``nodes``: those only, a process each (``split``); ``against``:
    with ``split``, the tree in that folder's nodes too (but the sim and features: ``"<node>
    @against"``), clients of their own; ``served``: filled with the TCP ports its clients connect to."""
    def show_ports() -> dict[str, int]:
        return {name: free_port(socket.SOCK_DGRAM if name in ("osc", "gateway") else socket.SOCK_STREAM)
                for name in ("osc", "gateway", "web", "oscquery", "foxglove")}
    ports = show_ports()
    config = folder / "show.toml"
    config.write_text(SHOW.format(rate=RATE_HZ, folder=folder, bus_options=BUS_OPTIONS, **ports))
    twins = [node for node in nodes if node not in ("sim", "features")] if split and against else []
    twin_ports = show_ports()
    if served is not None:
        served.update(port for name, port in (*ports.items(), *twin_ports.items()) if name not in ("osc", "gateway"))
    (folder / "against.toml").write_text(SHOW.format(rate=RATE_HZ, folder=folder, bus_options=BUS_OPTIONS,
                                                      **twin_ports))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    processes: dict[str, subprocess.Popen[bytes]] = {}
    manager = CONTEXT.Manager()
    counts, ready, done = manager.dict(), CONTEXT.Event(), CONTEXT.Event()
    twin_counts, twin_ready = manager.dict(), CONTEXT.Event()
    client = twin_client = None
    try:
        if split:  # (every node connects to a router, no node's process the others' meeting point; peers
            # still link to each other directly, learnt by gossip: the router's CPU is said apart, ~0.7 %)
            with open(folder / "router.log", "w") as out:
                processes["router"] = subprocess.Popen([SONIBUS, "router", "--no-multicast", "--listen", endpoint],
                                                       stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
            started(folder / "router.log", processes["router"], "sonibus router")
            for node in nodes:
                processes[node] = sonibus(config, folder / f"{node}.log", "--only", node, "--connect", endpoint)
            for node in twins:
                processes[f"{node} @against"] = sonibus(folder / "against.toml", folder / f"{node}-against.log",
                                                        "--only", node, "--connect", endpoint, tree=against)
            for node in nodes:
                started(folder / f"{node}.log", processes[node])
            for node in twins:
                started(folder / f"{node}-against.log", processes[f"{node} @against"])
        else:
            processes["show"] = sonibus(config, folder / "show.log", "--listen", endpoint, tree=tree)
            started(folder / "show.log", processes["show"])
        served = {name: port for name, port in ports.items() if name in nodes or name == "osc"}
        client = CONTEXT.Process(target=clients, args=(served, counts, ready, done), daemon=True)
        client.start()
        if twins:
            twin_served = {name: port for name, port in twin_ports.items() if name in twins or name == "osc"}
            twin_client = CONTEXT.Process(target=clients, args=(twin_served, twin_counts, twin_ready, done),
                                          daemon=True)
            twin_client.start()
        if not ready.wait(60) or (twins and not twin_ready.wait(60)):
            raise RuntimeError("the clients did not connect")
        deadline = time.monotonic() + 30  # (every client fed before the warm-up: a busy machine starts slowly)
        while (min((counts.get(name, 0) for name in ("osc", "web", "oscquery", "foxglove") if name in nodes),
                   default=1) == 0
               or any(twin_counts.get(name, 0) == 0 for name in ("osc", "web", "oscquery", "foxglove")
                      if name in twins)):
            if time.monotonic() > deadline or not client.is_alive():
                logs = {name: (folder / f"{name}.log").read_text(errors="replace")[-600:] for name in nodes}
                raise RuntimeError(f"a client received nothing: {dict(counts)}, {dict(twin_counts)}; {logs}")
            time.sleep(0.2)
        yield {name: p.pid for name, p in processes.items()}
    finally:
        done.set()
        for each in (client, twin_client):
            if each is not None:
                each.join(10)
                if each.is_alive():
                    each.kill()
        for process in processes.values():
            stop_process(process)
        manager.shutdown()


def measure_beside_floors(folder: Path, seconds: float, nodes: tuple[str, ...], against: str = "",
                          counted: dict[str, Any] | None = None) -> dict[str, dict[str, float]]:
    """The show in a process per node (``"split"``, ``show_running``'s) and every floor of its
    nodes (``"floors"``: ``floors_running``'s and ``node_floors``'), all running at once, CPU %
    over one window: a node and its floor measured in the same seconds, on the same machine
    (measured one after the other, a node's ratio to its floor moved by ±30 % from run to run
    on this VM, whose speed drifts over minutes).

    With ``LINKED`` (the default), each floor's process has as many Zenoh links as its node's
    (``FLOOR_OF``; ``bench/links.py``), the sessions of both at the same lease: ``counted``
    gets each floor's and its node's link ends."""
    if counted is None:
        counted = {}
    with contextlib.ExitStack() as running:
        links = Links() if LINKED else None
        if links is not None:
            running.callback(links.close)
        served: set[int] = set()
        floors = {**running.enter_context(floors_running(links=links)),
                  **running.enter_context(node_floors.running(tuple(n for n in node_floors.NODES if n in nodes),
                                                              links=links, served=served))}
        show = running.enter_context(show_running(folder, True, nodes=nodes, against=against, served=served))
        if links is not None:
            counted.update(links.match(floors, show, FLOOR_OF, frozenset(served)))
        time.sleep(WARMUP_S)
        cpu = window({**{f"floors/{name}": pid for name, pid in floors.items()},
                      **{f"split/{name}": pid for name, pid in show.items()}}, seconds)
    return {layout: {name.partition("/")[2]: value for name, value in cpu.items() if name.startswith(layout + "/")}
            for layout in ("floors", "split")}


@contextlib.contextmanager
def floors_running(seconds: float = 600.0, links: Links | None = None) -> Iterator[dict[str, int]]:
    """The minimal harnesses: publisher (the sim's floor, its frames taken by ``FRAME_TAKERS``
    sessions), an empty subscriber (a sink's floor),
    floor.py's OSC sink, one robot × 17 joints at ``RATE_HZ``, and the same sink fed a derived
    frame beside each frame (``floor.DERIVED``, a features node's shape): the show's OSC node
    sends joints and derived values, a datagram each. Fed for ``seconds`` at most; their
    process ids by name, once each is fed (not warmed up); stopped on leaving. With ``links``
    (``bench/links.py``), each one's process can be given idle links."""
    case = Case(1, 17)
    endpoints = [f"tcp/127.0.0.1:{free_port()}" for _ in range(3)]
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    ready, done = CONTEXT.Event(), CONTEXT.Event()
    empty = Links.process(links, "subscriber", empty_subscriber, (endpoints[0], ready, done))
    sinks, readies = [], [ready]
    for endpoint, derived in zip(endpoints[1:], (False, True), strict=True):
        readies.append(CONTEXT.Event())
        sinks.append(Links.process(links, "osc sink + derived" if derived else "osc sink", floor_sink,
                                   (endpoint, receiver.getsockname()[1], case, readies[-1], done), derived=derived))
    fed_all = CONTEXT.Event()  # (the publisher's other takers: sessions of their own, each fed before measuring)
    takers = CONTEXT.Process(target=takers_of, args=(endpoints[0], FRAME_TAKERS - 1, fed_all, done), daemon=True)
    for process in (empty, *sinks):
        process.start()
    feeders = []
    try:
        if not all(event.wait(30) for event in readies):
            raise RuntimeError("the floor harnesses did not start")
        takers.start()
        handles = []  # (kept until the end: a queue collected here is gone for the child too)
        for endpoint, derived in zip(endpoints, (False, False, True), strict=True):
            fed, out = CONTEXT.Event(), CONTEXT.Queue()
            if feeders:  # (the others feed a floor)
                feeders.append(CONTEXT.Process(target=publish, args=(endpoint, case, seconds, fed, out),
                                               kwargs={"rate_hz": RATE_HZ, "derived": derived}, daemon=True))
            else:  # (the first is the sim's floor)
                feeders.append(Links.process(links, "publisher", publish, (endpoint, case, seconds, fed, out),
                                             rate_hz=RATE_HZ, derived=derived))
            feeders[-1].start()
            handles.append((fed, out))
        if not all(fed.wait(30) for fed, _ in handles) or not fed_all.wait(30):
            raise RuntimeError("the floor publishers did not find their subscribers")
        yield {"publisher": feeders[0].pid, "subscriber": empty.pid, "osc sink": sinks[0].pid,
               "osc sink + derived": sinks[1].pid}
    finally:
        done.set()
        for process in feeders:  # (they would publish until their time is up)
            process.kill()
        for process in (*feeders, empty, *sinks, takers):
            if process.pid is None:  # (never started)
                continue
            process.join(10)
            if process.is_alive():
                process.kill()
        receiver.close()


def takers_of(endpoint: str, count: int, fed: Any, done: Any) -> None:
    """``count`` sessions (one process), each connected to ``endpoint`` and taking the frames
    with an empty callback: the publisher's frames go to each (its session learns them by
    gossip and links to each, as the sim's links to each node's); ``fed`` once each has one."""
    import zenoh
    sessions = [zenoh.open(zenoh_config(connect=endpoint)) for _ in range(count)]
    got = [threading.Event() for _ in sessions]
    subscribers = [session.declare_subscriber("*/frame", lambda sample, event=event: event.set())
                   for session, event in zip(sessions, got, strict=True)]
    for event in got:
        if not event.wait(30):
            return  # (said by the caller: fed is never set)
    fed.set()
    done.wait()
    for subscriber, session in zip(subscribers, sessions, strict=True):
        subscriber.undeclare()
        session.close()


def empty_subscriber(endpoint: str, ready: Any, done: Any) -> None:
    """Receives the frames and does nothing with them."""
    import zenoh
    session = zenoh.open(zenoh_config(listen=endpoint))
    subscriber = session.declare_subscriber("*/frame", lambda sample: None)
    ready.set()
    done.wait()
    subscriber.undeclare()
    session.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=8.0, help="measuring window of each layout and round")
    parser.add_argument("--name", default="show", help="results file name (show_before: an older tree)")
    parser.add_argument("--one-process", action="store_true",
                        help="only the show in one process (no floors, no process per node)")
    parser.add_argument("--against", metavar="DIR", default="",
                        help="with --one-process: each round also the show on the tree in DIR (DIR/sonibus/{bus,...}); "
                             "with --nodes: those nodes of that tree beside them, on the same bus")
    parser.add_argument("--nodes", default="", help="comma-separated: only these nodes (with the sim and features "
                        "that feed them), a process each, and their floors; no one-process layout")
    parser.add_argument("--lease-ms", type=int, default=0,
                        help="the show's Zenoh lease (its nodes' [bus] lease_ms; 0: sonibus's default)")
    parser.add_argument("--private-floors", action="store_true",
                        help="the floors on private pairs of sessions, without their nodes' links (as before 30 Nov)")
    args = parser.parse_args()
    global BUS_OPTIONS, LINKED
    LINKED = not args.private_floors
    if args.lease_ms:
        BUS_OPTIONS = f"\nlease_ms = {args.lease_ms}"
        os.environ["BENCH_LEASE_MS"] = str(args.lease_ms)  # (the floors' too: bench/common.lease_ms)
    chosen = tuple(node for node in args.nodes.split(",") if node)
    if unknown := set(chosen) - set(NODES):
        parser.error(f"--nodes {args.nodes}: no node {', '.join(sorted(unknown))} (the show's: {', '.join(NODES)})")
    nodes = tuple(node for node in NODES if node in {"sim", "features", *chosen}) if chosen else NODES
    if args.one_process:
        one_process(args)
        return
    load = [os.getloadavg()[0]]
    rounds: list[dict[str, dict[str, float]]] = []
    links: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        jack = start_jack(folder / "jackd.log")
        try:
            for index in range(args.rounds):
                got: dict[str, dict[str, float]] = {}
                counted: dict[str, Any] = {}  # (each floor's link ends and its node's, LINKED)
                for split in ((True,) if chosen else (True, False) if index % 2 == 0 else (False, True)):
                    if split:
                        got.update(measure_beside_floors(folder, args.seconds, nodes, args.against if chosen else "",
                                                         counted))
                    else:
                        got["one"] = measure_show(folder, args.seconds, False)
                rounds.append(got)
                links.append(counted)
                load.append(os.getloadavg()[0])
                print(f"round {index + 1}: " + "; ".join(f"{layout}: " + ", ".join(
                    f"{node} {cpu:.1f} %" for node, cpu in values.items()) for layout, values in got.items()),
                    flush=True)
        finally:
            stop_process(jack, timeout=5)
            for leftover in Path("/dev/shm").glob(f"jack_sem.*_{os.environ.get('JACK_DEFAULT_SERVER')}_*"):
                leftover.unlink(missing_ok=True)
    med = {layout: {node: statistics.median(r[layout][node] for r in rounds) for node in rounds[0][layout]}
           for layout in rounds[0]}
    machine = f"{os.cpu_count()} cores, load {min(load):.2f}–{max(load):.2f}"
    tree = os.environ.get("PYTHONPATH", "") or "this tree"
    floors = med["floors"]
    cpus = {node: cpu for node, cpu in med["split"].items() if node != "router"}
    summary = [{"scenario": f"(show) one process, every node, 1 robot at {RATE_HZ} Hz, clients attached: CPU",
                "sonibus": f"{med['one']['show']:.1f} %",
                "baseline": f"{sum(cpus.values()):.1f} % as a process per node (and their router "
                            f"{med['split'].get('router', 0.0):.1f} %)", "ratio": "",
                "goal": f"≤ {SHOW_GOAL_PCT:g} % of a core",
                "met": "yes" if med["one"]["show"] <= SHOW_GOAL_PCT else "no"}] if "one" in med else []
    for node, cpu in cpus.items():
        if node.endswith(" @against"):  # (the same node of another tree, beside it: the row of this tree's says it)
            continue
        if f"{node} @against" in cpus:
            summary.append({"scenario": f"(show) {node} node, own process, beside {args.against}'s on one bus: CPU",
                            "sonibus": f"{cpu:.1f} %", "baseline": f"{cpus[node + ' @against']:.1f} %",
                            "ratio": f"{cpu / cpus[node + ' @against']:.2f}×"})
        floor = ("publisher" if node == "sim" else "osc sink + derived" if node == "osc"
                 else node if node in floors and node in node_floors.NODES else "subscriber")
        base = floors[floor]
        label = ("publisher" if node == "sim" else "minimal OSC sink of joints and derived values" if node == "osc"
                 else f"{node} floor" if floor == node else "empty subscriber")  # (their own: bench/node_floors.py)
        if LINKED and floor in links[-1]:
            label += f", {links[-1][floor]['node']} Zenoh links as the node's"
        ratio = f"{cpu / base:.2f}×"
        if node == "osc":
            label += f"; of joints only {floors['osc sink']:.1f} %"
            ratio += f" ({cpu / floors['osc sink']:.2f}× the joints-only floor)"
        summary.append({"scenario": f"(show) {node} node, own process: CPU", "sonibus": f"{cpu:.1f} %",
                        "baseline": f"{base:.1f} % ({label})", "ratio": ratio,
                        "goal": f"≤ {NODE_GOAL:g}× its floor", "met": "yes" if cpu <= NODE_GOAL * base else "no"})
    write(args.name, {"machine": machine, "tree": tree, "rate_hz": RATE_HZ, "seconds": args.seconds,
                      "lease_ms": args.lease_ms or None,
                      "floors_linked": LINKED, "links": links, "rounds": rounds, "median": med, "summary": summary})
    for layout, values in med.items():
        print(f"{layout:>7}: " + ", ".join(f"{node} {cpu:.2f} %" for node, cpu in values.items()))
    print(machine, tree)


def one_process(args: argparse.Namespace) -> None:
    """The show in one process only, and (``--against``) on another tree in the same rounds,
    their order alternating: a change's before and after, nothing else between."""
    load = [os.getloadavg()[0]]
    trees = {"this tree": "", **({args.against: args.against} if args.against else {})}
    rounds: list[dict[str, float]] = []
    switched: list[dict[str, float]] = []  # voluntary context switches a second, by tree
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        jack = start_jack(folder / "jackd.log")
        try:
            for index in range(args.rounds):
                order = list(trees.items()) if index % 2 == 0 else list(reversed(trees.items()))
                got, waits = {}, {}
                for label, tree in order:
                    counted: dict[str, float] = {}
                    got[label] = measure_show(folder, args.seconds, False, tree, counted)["show"]
                    waits[label] = counted["show"]
                rounds.append(got)
                switched.append(waits)
                load.append(os.getloadavg()[0])
                print(f"round {index + 1}: " + ", ".join(f"{label} {cpu:.1f} % ({waits[label]:.0f} switches/s)"
                                                         for label, cpu in got.items()), flush=True)
        finally:
            stop_process(jack, timeout=5)
            for leftover in Path("/dev/shm").glob(f"jack_sem.*_{os.environ.get('JACK_DEFAULT_SERVER')}_*"):
                leftover.unlink(missing_ok=True)
    med = {label: statistics.median(r[label] for r in rounds) for label in trees}
    machine = f"{os.cpu_count()} cores, load {min(load):.2f}–{max(load):.2f}"
    summary = [{"scenario": f"(show) one process, every node, 1 robot at {RATE_HZ} Hz, clients attached: CPU",
                "sonibus": f"{med['this tree']:.1f} %",
                "baseline": f"{med[args.against]:.1f} % ({args.against})" if args.against else "",
                "ratio": f"{med['this tree'] / med[args.against]:.2f}×" if args.against else ""}]
    write(args.name, {"machine": machine, "rate_hz": RATE_HZ, "seconds": args.seconds, "rounds": rounds,
                      "median": med, "switches_per_s": switched, "summary": summary})
    print(", ".join(f"{label} {cpu:.2f} %" for label, cpu in med.items()), machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks (jackd)
    main()
