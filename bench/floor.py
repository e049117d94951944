"""The floor of the stack (issue 27): the OSC sink beside a minimal harness that does
the same work with the same libraries and imports no sonibus, in the same run.

Every path gets the same input and is measured the same way:

- publishers: one process, a zenoh-python publisher per robot putting a msgpack
  frame (``{t, seq, names, v}``, as a robot owner's ``<robot>/frame``) of N floats
  at 100 Hz (``DATA_HIGH``, drop, batched); it connects to the sink under test;
- **floor**: a zenoh-python subscriber process (listening on loopback TCP,
  multicast off) whose callback unpacks each frame and sends N OSC datagrams
  built from precomputed address bytes and one ``struct.pack`` each (``,fdi``:
  value, t, seq) — or, for bundles, one bundle of them;
- **sonibus**: ``sonibus run`` with one ``osc`` node (``extra = ["t", "seq"]``,
  the same datagrams; ``bundle = true`` for bundles);
- **no bus**: one process sends the same datagrams straight, paced the same way;
- receiver processes (one for sonibus's datagrams, one for the others') note each
  datagram's arrival (the kernel's receive stamp, ``SO_TIMESTAMPNS``) − its ``t``.

CPU is the sink process's own, summed over its threads from
``/proc/<pid>/task/*/schedstat`` over the measuring window (after a warm-up).
The floor and sonibus run in the same window, each fed by a publisher process of its
own (this VM's speed drifts over minutes: measured one after the other, a sink's ratio
to its floor moved by ±0.15 from run to run); no bus in a window of its own, before
or after them, alternating; the figures are medians over rounds and every sonibus
figure is stated as a ratio to the floor (and to no bus) of the same run. The sinks
run from start to end; a publisher process per path and window feeds each one
measured (no two sessions are linked, so the others idle). Every session has
sonibus's lease (``common.lease_ms``).

    .venv/bin/python bench/floor.py [--rounds 3] [--seconds 4] [--only 2x17 2x17b]

Writes bench/results/floor.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import math
import multiprocessing as mp
import os
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common import free_port, latency_stats, osc_messages, write, zenoh_config
from sink_throughput import sink_stats, stop_process

CONTEXT = mp.get_context("spawn")  # never fork a process that has opened a Zenoh session
SONIBUS = str(Path(sys.executable).with_name("sonibus"))
RATE_HZ = 100.0
WARMUP_S = 1.0
SLACK_S = 2.0  # paths measured at once: how much later than the first the last may find its sink
NTP_OFFSET = 2208988800
CONNECTED = "floor (connected)"
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux: the kernel's receive time, in ns


@dataclass(frozen=True)
class Case:
    """One shape of load: ``robots`` × ``joints`` at 100 Hz, plain messages or bundles."""

    robots: int
    joints: int
    bundle: bool = False

    @property
    def name(self) -> str:
        return f"{self.robots}x{self.joints}{'b' if self.bundle else ''}"


# a features node's derived frame for a Pepper, in shape: 17 joint velocities, 2 hand
# positions (3-vectors), 7 expressive values (``floor_sink(derived=True)``, bench/show.py)
DERIVED = ([(f"velocity/J{j}", 1) for j in range(17)] + [("hand/L", 3), ("hand/R", 3)]
           + [(f"expressive/E{e}", 1) for e in range(7)])
CASES = [Case(1, 17), Case(2, 17), Case(10, 17), Case(2, 64), Case(2, 128), Case(2, 17, True), Case(10, 17, True)]


# -- the datagrams: what every path sends (no sonibus) ----------------------------------


def _padded(text: str) -> bytes:
    data = text.encode()
    return data + b"\0" * (4 - len(data) % 4)


class Datagrams:
    """The OSC a path sends for one frame of robot ``r``: precomputed address and type tag
    bytes per joint, one ``struct.pack`` per message; a bundle's element sizes too."""

    PACK = struct.Struct(">fdi").pack  # value, t (double), seq
    PACK3 = struct.Struct(">fffdi").pack  # a 3-vector, t, seq

    def __init__(self, robots: int, joints: int) -> None:
        self.prefixes = {f"robot{r}/frame": [_padded(f"/robot{r}/joints/J{j}") + _padded(",fdi")
                                             for j in range(joints)] for r in range(robots)}
        self.sized = {key: [struct.pack(">i", len(p) + 16) + p for p in prefixes]
                      for key, prefixes in self.prefixes.items()}
        self._derived: dict[str, list[bytes]] = {}

    def derived(self, robot: str, t: float, seq: int, values: list[Any]) -> list[bytes]:
        """A derived frame's datagrams (``DERIVED``: scalars ``,fdi``, 3-vectors ``,fffdi``)."""
        prefixes = self._derived.get(robot)
        if prefixes is None:
            prefixes = self._derived[robot] = [
                _padded(f"/{robot}/derived/{name}") + _padded(",fffdi" if size == 3 else ",fdi")
                for name, size in DERIVED]
        pack, pack3 = self.PACK, self.PACK3
        return [prefix + (pack3(*v, t, seq) if v.__class__ is list else pack(v, t, seq))
                for prefix, v in zip(prefixes, values, strict=True)]

    def messages(self, key: str, t: float, seq: int, values: list[float]) -> list[bytes]:
        pack = self.PACK
        return [prefix + pack(v, t, seq) for prefix, v in zip(self.prefixes[key], values, strict=True)]

    def bundle(self, key: str, t: float, seq: int, values: list[float]) -> bytes:
        pack, seconds = self.PACK, t + NTP_OFFSET
        whole = int(seconds)
        head = b"#bundle\0" + struct.pack(">Q", (whole << 32) | int((seconds - whole) * 2**32))
        return head + b"".join([sized + pack(v, t, seq) for sized, v in zip(self.sized[key], values, strict=True)])


# -- processes ------------------------------------------------------------------------------


def publish(endpoint: str, case: Case, seconds: float, ready: Any, out: Any, rate_hz: float = RATE_HZ,
            derived: bool = False) -> None:
    """A publisher per robot on ``robot<r>/frame``, ``rate_hz`` frames/s each, for ``seconds``;
    with ``derived``, a derived frame of ``DERIVED`` values beside each (``robot<r>/derived``,
    as a features node publishes them)."""
    import msgpack
    import zenoh
    session = zenoh.open(zenoh_config(connect=endpoint))
    options = {"priority": zenoh.Priority.DATA_HIGH, "congestion_control": zenoh.CongestionControl.DROP,
               "express": False}
    publishers = [session.declare_publisher(f"robot{r}/frame", **options) for r in range(case.robots)]
    extras = [session.declare_publisher(f"robot{r}/derived", **options) for r in range(case.robots)] if derived else []
    deadline = time.monotonic() + 20
    while not all(p.matching_status.matching for p in publishers + extras) and time.monotonic() < deadline:
        time.sleep(0.02)
    names = [f"J{j}" for j in range(case.joints)]
    derived_names = [name for name, _ in DERIVED]
    ready.set()
    period, start, frame, put = 1.0 / rate_hz, time.monotonic(), 0, 0
    while time.monotonic() - start < seconds:
        for r, publisher in enumerate(publishers):
            t = time.time()
            values = [math.sin(t + 0.1 * j + r) for j in range(case.joints)]
            publisher.put(msgpack.packb({"t": t, "seq": frame, "names": names, "v": values}))
            if extras:
                extras[r].put(msgpack.packb({"t": t, "seq": frame, "names": derived_names,
                                             "v": [[v, v, v] if size == 3 else v
                                                   for (_, size), v in zip(DERIVED, values * 2, strict=False)]}))
            put += 1
        frame += 1
        late = time.monotonic() - (start + frame * period)
        if late > period:  # skip, never burst (as a robot owner's pacer)
            frame += int(late / period)
        time.sleep(max(0.0, start + frame * period - time.monotonic()))
    out.put(put)
    for publisher in publishers:
        publisher.undeclare()
    session.close()


def floor_sink(endpoint: str, port: int, case: Case, ready: Any, done: Any, connected: bool = False,
               derived: bool = False) -> None:
    """The minimal sink: unpack, then the precomputed datagrams (or one bundle) per frame;
    ``connected``: sent on a connected socket (``send``), as the sonibus sink sends them,
    rather than with ``sendto`` (the floor as issue 27 defined it); ``derived``: derived
    frames too (``robot<r>/derived``), a datagram a value (the show's OSC node's work)."""
    import msgpack
    import zenoh
    datagrams = Datagrams(case.robots, case.joints)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    destination = ("127.0.0.1", port)
    if connected:
        sock.connect(destination)
        send = sock.send
    else:
        def send(datagram: bytes) -> None:
            sock.sendto(datagram, destination)

    def each_derived(sample: Any) -> None:
        frame = msgpack.unpackb(sample.payload.to_bytes())
        for datagram in datagrams.derived(str(sample.key_expr).split("/")[0], frame["t"], frame["seq"], frame["v"]):
            send(datagram)

    def each(sample: Any) -> None:
        frame = msgpack.unpackb(sample.payload.to_bytes())
        key = str(sample.key_expr)
        if case.bundle:
            send(datagrams.bundle(key, frame["t"], frame["seq"], frame["v"]))
            return
        for datagram in datagrams.messages(key, frame["t"], frame["seq"], frame["v"]):
            send(datagram)

    session = zenoh.open(zenoh_config(listen=endpoint))
    subscribers = [session.declare_subscriber("*/frame", each)]
    if derived:
        subscribers.append(session.declare_subscriber("*/derived", each_derived))
    ready.set()
    done.wait()
    for subscriber in subscribers:
        subscriber.undeclare()
    session.close()


def no_bus(port: int, case: Case, seconds: float, ready: Any, out: Any) -> None:
    """The same datagrams sent straight, paced like the publishers."""
    datagrams = Datagrams(case.robots, case.joints)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    destination = ("127.0.0.1", port)
    ready.set()
    period, start, frame, sent = 1.0 / RATE_HZ, time.monotonic(), 0, 0
    while time.monotonic() - start < seconds:
        for r in range(case.robots):
            t = time.time()
            values = [math.sin(t + 0.1 * j + r) for j in range(case.joints)]
            key = f"robot{r}/frame"
            if case.bundle:
                sock.sendto(datagrams.bundle(key, t, frame, values), destination)
            else:
                for datagram in datagrams.messages(key, t, frame, values):
                    sock.sendto(datagram, destination)
            sent += 1
        frame += 1
        time.sleep(max(0.0, start + frame * period - time.monotonic()))
    out.put(sent)


def receive(port: int, ready: Any, control: Any, out: Any) -> None:
    """Note (kernel arrival − t) of every message, from ``control``'s "start" to its "stop";
    and (the receiver's clock once ``recvmsg`` returned − t), as issue 27 measured latency:
    what a receiver's program sees, its own wake-up included."""
    gc.disable()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.05)
    ready.set()
    latencies: list[float] | None = None
    woken: list[float] = []
    frames: set[tuple[bytes, int]] = set()
    messages = 0
    while True:
        while not control.empty():
            command = control.get()
            if command == "start":
                latencies, woken, frames, messages = [], [], set(), 0
            elif command == "stop":
                out.put({"latencies": latencies or [], "woken": woken, "messages": messages, "frames": len(frames)})
                latencies = None
            else:
                return
        try:
            data, ancillary, _, _ = sock.recvmsg(65536, 64)
        except TimeoutError:
            continue
        if latencies is None:
            continue
        arrival = woke = time.time()
        for level, kind, stamp in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                seconds, nanoseconds = struct.unpack("qq", stamp[:16])
                arrival = seconds + nanoseconds * 1e-9
        for message in osc_messages(data):
            t, seq = struct.unpack(">di", message[-12:])
            latencies.append(arrival - t)
            woken.append(woke - t)
            frames.add((message[:12], seq))
            messages += 1


def cpu_ns(pid: int) -> int:
    """CPU time of every thread of ``pid`` so far (``/proc/<pid>/task/*/schedstat``), in ns."""
    total = 0
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/schedstat") as f:
                total += int(f.read().split()[0])
        except (FileNotFoundError, ProcessLookupError):  # a thread that just ended
            continue
    return total


def switches(pid: int) -> int:
    """Context switches of every thread of ``pid`` so far (voluntary: a thread that waits and is
    woken; from ``/proc/<pid>/task/*/status``): a count the machine's load does not blur."""
    total = 0
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/status") as f:
                total += sum(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt_switches"))
        except (FileNotFoundError, ProcessLookupError):  # a thread that just ended
            continue
    return total


# -- the run --------------------------------------------------------------------------------


class Receiver:
    """A ``receive`` process on a port of its own, told when to start and stop noting."""

    def __init__(self) -> None:
        self.port = free_port(socket.SOCK_DGRAM)
        ready, self.control, self.results = CONTEXT.Event(), CONTEXT.Queue(), CONTEXT.Queue()
        self.process = CONTEXT.Process(target=receive, args=(self.port, ready, self.control, self.results),
                                       daemon=True)
        self.process.start()
        if not ready.wait(20):
            raise RuntimeError("the receiver did not start")

    def close(self) -> None:
        self.control.put("quit")
        self.process.join(10)
        if self.process.is_alive():
            self.process.kill()


class Bench:
    """The receivers and the sinks, up from start to end; ``measure_at_once`` runs one window
    of one path or several (sonibus's datagrams go to a receiver of their own, the others' to
    another)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.receivers = {"sonibus": Receiver(), "others": Receiver()}
        self.sinks: dict[tuple[str, str], tuple[Any, str]] = {}  # (path, case) → (process, endpoint)
        self.done = CONTEXT.Event()
        self.logs: dict[str, Path] = {}

    def receiver(self, path: str) -> Receiver:
        return self.receivers["sonibus" if path == "sonibus" else "others"]

    def sink(self, path: str, case: Case) -> tuple[int, str]:
        """The pid and endpoint of ``path``'s sink for ``case`` (started on first use)."""
        key = (path, case.name)
        if key not in self.sinks:
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            if path.startswith("floor"):
                ready = CONTEXT.Event()
                process = CONTEXT.Process(target=floor_sink, args=(endpoint, self.receiver(path).port, case, ready,
                                                                   self.done,
                                                                   path == CONNECTED),
                                          daemon=True)
                process.start()
                if not ready.wait(20):
                    raise RuntimeError("the floor sink did not start")
            else:
                process = self._sonibus(endpoint, case)
            self.sinks[key] = (process, endpoint)
        process, endpoint = self.sinks[key]
        return process.pid, endpoint

    def _sonibus(self, endpoint: str, case: Case) -> subprocess.Popen[bytes]:
        config = self.folder / f"sink-{case.name}.toml"
        config.write_text(f'[bus]\nmulticast = false\n\n[nodes.sound]\nadapter = "osc"\nsubscribe = "*/joints/*"\n'
                          f'targets = ["127.0.0.1:{self.receivers["sonibus"].port}"]\nextra = ["t", "seq"]\n'
                          f'bundle = {str(case.bundle).lower()}\n')
        log = self.logs[case.name] = self.folder / f"sink-{case.name}.log"
        with open(log, "w") as stderr:
            process = subprocess.Popen([SONIBUS, "-v", "run", str(config), "--no-multicast", "--listen", endpoint],
                                       stdout=subprocess.DEVNULL, stderr=stderr, start_new_session=True)
        deadline = time.monotonic() + 30
        while "started" not in log.read_text():
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"sonibus did not start: {log.read_text()[-2000:]}")
            time.sleep(0.1)
        return process

    def measure_at_once(self, paths: tuple[str, ...], case: Case, seconds: float) -> dict[str, dict[str, Any]]:
        """One window of every path of ``paths`` (each fed by a publisher process of its own, its
        datagrams to a receiver of its own) for ``case``: by path, latencies, messages and the
        sink's CPU. Measured in the same seconds, a sink and its floor see the same machine (this
        VM's speed drifts over minutes: measured one after the other, a ratio moved by ±0.15)."""
        if len({self.receiver(path).port for path in paths}) != len(paths):
            raise ValueError(f"{paths}: two paths would share a receiver")
        feeders, pids, endpoints = {}, {}, {}
        for path in paths:  # (every sink up before any is fed: a sonibus starting takes a second or two)
            if path != "no bus":
                pids[path], endpoints[path] = self.sink(path, case)
        # (each feeds from when it found its sink: with ``slack`` more, none stops before the window ends)
        slack = SLACK_S if len(paths) > 1 else 0.0
        for path in paths:
            ready, out = CONTEXT.Event(), CONTEXT.Queue()
            if path == "no bus":
                feeder = CONTEXT.Process(target=no_bus, args=(self.receiver(path).port, case,
                                                              seconds + WARMUP_S + slack, ready, out), daemon=True)
            else:
                feeder = CONTEXT.Process(target=publish, args=(endpoints[path], case, seconds + WARMUP_S + slack,
                                                               ready, out), daemon=True)
            feeders[path] = (feeder, ready, out)
            feeder.start()
        received = {}
        try:
            if not all(ready.wait(30) for _, ready, _ in feeders.values()):
                raise RuntimeError(f"{paths}: the publishers did not find the sinks")
            time.sleep(WARMUP_S)
            for path in paths:
                self.receiver(path).control.put("start")
            cpu0, wall0 = {path: cpu_ns(pid) for path, pid in pids.items()}, time.monotonic()
            time.sleep(seconds)
            cpu, wall = {path: cpu_ns(pid) - cpu0[path] for path, pid in pids.items()}, time.monotonic() - wall0
            for path in paths:
                self.receiver(path).control.put("stop")
            for path in paths:
                received[path] = self.receiver(path).results.get(timeout=30)
                feeders[path][2].get(timeout=30)
        finally:
            for feeder, _, _ in feeders.values():
                feeder.join(10)
                if feeder.is_alive():
                    feeder.kill()
        nan = {"p50_us": math.nan, "p99_us": math.nan}
        expected = case.robots * case.joints * RATE_HZ * seconds  # messages (a bundle holds a frame's)
        measured = {}
        for path in paths:
            got = received[path]
            stats = latency_stats(got["latencies"]) if got["latencies"] else nan
            woken = latency_stats(got["woken"]) if got["woken"] else nan
            measured[path] = {"p50_us": stats["p50_us"], "p99_us": stats["p99_us"], "woken_p50_us": woken["p50_us"],
                              "messages": got["messages"], "delivered": got["messages"] / expected,
                              "cpu_pct": 100.0 * cpu[path] / 1e9 / wall if path in cpu else None}
        return measured

    def close(self) -> dict[str, dict[str, int]]:
        """Stop everything; each sonibus sink's counters (from its last log line)."""
        self.done.set()
        counters = {}
        for (path, name), (process, _) in self.sinks.items():
            if path.startswith("floor"):
                process.join(10)
                if process.is_alive():
                    process.kill()
            else:
                stop_process(process)
                counters[name] = sink_stats(self.logs[name].read_text())
        for receiver in self.receivers.values():
            receiver.close()
        return counters


def median(values: list[float]) -> float:
    kept = [v for v in values if v is not None and not math.isnan(v)]
    return statistics.median(kept) if kept else math.nan


def summarize(case: Case, rounds: list[dict[str, dict[str, Any]]], counters: dict[str, int]) -> dict[str, Any]:
    """Medians over rounds per path, and the ratios of sonibus to the floor and to no bus."""
    paths = {path: {k: median([r[path][k] for r in rounds])
                    for k in ("p50_us", "p99_us", "woken_p50_us", "cpu_pct", "delivered")}
             for path in rounds[0]}
    bus, floor, direct = paths["sonibus"], paths["floor"], paths["no bus"]
    return {"case": case.name, "robots": case.robots, "joints": case.joints, "bundle": case.bundle,
            "paths": paths, "rounds": rounds, "sink": counters,
            "cpu_per_robot_pct": {p: paths[p]["cpu_pct"] / case.robots for p in paths if p != "no bus"},
            "ratio_to_floor": {k: bus[k] / floor[k] for k in ("cpu_pct", "p50_us", "p99_us")},
            "ratio_to_connected_floor": ({k: bus[k] / paths[CONNECTED][k] for k in ("cpu_pct", "p50_us", "p99_us")}
                                         if CONNECTED in paths else None),
            "ratio_to_no_bus": {k: bus[k] / direct[k] for k in ("p50_us", "p99_us", "woken_p50_us")}}


def summary_rows(cases: list[dict[str, Any]]) -> list[dict[str, str]]:
    """The rows of bench/run.py's table, with the goals of issue 27."""
    rows = []
    for c in cases:
        floor, bus, direct = c["paths"]["floor"], c["paths"]["sonibus"], c["paths"]["no bus"]
        cpu = c["cpu_per_robot_pct"]
        ratio = c["ratio_to_floor"]
        shape = f"{c['robots']} robot(s) × {c['joints']} × 100 Hz → OSC" + (" (bundle = true)" if c["bundle"] else "")
        stale, skipped = c["sink"].get("stale", "?"), c["sink"].get("skipped", "?")
        goal, met = "", ""
        if c["joints"] == 17 and c["robots"] in (2, 10):  # (issue 35: bundles to the floor's own bundle path)
            goal = "CPU and p50 ≤ 1.2× floor" + ("'s bundle path" if c["bundle"] else "")
            met = ratio["cpu_pct"] <= 1.2 and ratio["p50_us"] <= 1.2
        elif c["joints"] == 128:
            goal, met = "keeps up, 0 stale", stale == 0 and bus["delivered"] >= 0.99
        rows.append({
            "scenario": f"(floor) {shape}: sink CPU per robot, p50 / p99",
            "sonibus": f"{cpu['sonibus']:.2f} %, {bus['p50_us']:,.0f} / {bus['p99_us']:,.0f} µs, "
                       f"{100 * bus['delivered']:.1f} % delivered, stale {stale}, skipped {skipped}",
            "baseline": f"floor {cpu['floor']:.2f} %, {floor['p50_us']:,.0f} / {floor['p99_us']:,.0f} µs; "
                        + (f"floor connected {cpu[CONNECTED]:.2f} %; " if CONNECTED in cpu else "")
                        + f"no bus {direct['p50_us']:,.0f} / {direct['p99_us']:,.0f} µs",
            "ratio": f"CPU {ratio['cpu_pct']:.2f}×, p50 {ratio['p50_us']:.2f}× / p99 {ratio['p99_us']:.2f}× floor; "
                     f"p50 {c['ratio_to_no_bus']['p50_us']:.2f}× no bus "
                     f"({c['ratio_to_no_bus']['woken_p50_us']:.2f}× by the receiver's clock)"
                     + (f"; CPU {c['ratio_to_connected_floor']['cpu_pct']:.2f}× floor connected"
                        if c.get("ratio_to_connected_floor") else ""),
            "goal": goal, "met": ("yes" if met else "no") if goal else ""})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds; paths interleaved in each")
    parser.add_argument("--seconds", type=float, default=4.0, help="measuring window of each path and round")
    parser.add_argument("--only", nargs="+", choices=[c.name for c in CASES], help="these cases only")
    parser.add_argument("--name", default="floor", help="results file name")
    parser.add_argument("--connected-floor", action="store_true",
                        help=f"also '{CONNECTED}': the floor sending on a connected socket, as the sonibus sink does")
    args = parser.parse_args()
    cases = [c for c in CASES if not args.only or c.name in args.only]
    load = [os.getloadavg()[0]]
    rounds: dict[str, list[dict[str, dict[str, Any]]]] = {c.name: [] for c in cases}
    with tempfile.TemporaryDirectory() as folder:
        bench = Bench(Path(folder))
        try:
            for index in range(args.rounds):
                for case in cases:
                    # (the floor and sonibus in one window; no bus, their latency's reference, in one of its own)
                    windows = [("no bus",), *([(CONNECTED,)] if args.connected_floor else []), ("floor", "sonibus")]
                    windows = windows if index % 2 == 0 else windows[::-1]
                    got = {}
                    for paths in windows:
                        got.update(bench.measure_at_once(paths, case, args.seconds))
                    order = [path for paths in windows for path in paths]
                    rounds[case.name].append(got)
                    print(f"round {index + 1} {case.name:>6}: " + ", ".join(
                        f"{p} {got[p]['p50_us']:.0f}/{got[p]['p99_us']:.0f} µs"
                        + (f" {got[p]['cpu_pct']:.2f} %" if got[p]["cpu_pct"] is not None else "")
                        for p in order), flush=True)
                load.append(os.getloadavg()[0])
        finally:
            counters = bench.close()
    results = [summarize(c, rounds[c.name], counters.get(c.name, {})) for c in cases]
    machine = f"{os.cpu_count()} cores, load {min(load):.2f}–{max(load):.2f}"
    write(args.name, {"machine": machine, "seconds": args.seconds, "rounds": args.rounds, "cases": results,
                      "summary": summary_rows(results)})
    print(f"{'case':>6} {'path':>8} {'p50 µs':>8} {'p99 µs':>8} {'CPU %/robot':>11} {'delivered':>9}")
    for c in results:
        for path, p in c["paths"].items():
            cpu = f"{p['cpu_pct'] / c['robots']:.2f}" if not math.isnan(p["cpu_pct"]) else "-"
            print(f"{c['case']:>6} {path:>8} {p['p50_us']:>8.0f} {p['p99_us']:>8.0f} {cpu:>11} "
                  f"{100 * p['delivered']:>8.1f}%")
        ratio, connected = c["ratio_to_floor"], c["ratio_to_connected_floor"]
        print(f"{'':>6} ratio to floor: CPU {ratio['cpu_pct']:.2f}, p50 {ratio['p50_us']:.2f}, "
              f"p99 {ratio['p99_us']:.2f}"
              + (f"; to {CONNECTED}: CPU {connected['cpu_pct']:.2f}, p50 {connected['p50_us']:.2f}"
                 if connected else "")
              + f"; p50 to no bus {c['ratio_to_no_bus']['p50_us']:.2f} "
              f"(receiver's clock {c['ratio_to_no_bus']['woken_p50_us']:.2f}); sink counters {c['sink']}")
    print(machine)


if __name__ == "__main__":
    main()
