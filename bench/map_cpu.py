"""CPU of the map node: 50 maps on a Pepper's frames at 100 Hz, beside a minimal harness
doing the same arithmetic in the same run; and source-to-OSC latency through a map.

- map node: a robot (its info served, its frames put on ``pepper/frame`` at 100 Hz, 17
  joints moving) and a ``map`` node with 50 maps over its joints (linear, exp, log, s
  curves; one-pole smoothing on half, a one-euro filter on a quarter, a threshold on a
  tenth), connected over loopback; CPU time of the node's worker thread (take the frame,
  map, encode and put 50 outputs) as % of one core.
- harness, same run, same frames: one thread takes each frame from a Zenoh subscriber's
  queue, decodes it, does the same arithmetic written out by hand (fraction, curve, scale,
  one-pole) for 50 outputs, encodes them and puts them on 50 publishers.
- latency, same run: the robot's ``t`` of each HeadYaw to its arrival at a UDP socket, through
  a map (exp curve, one-pole) and an OSC sink, beside HeadYaw straight through an OSC sink.

    .venv/bin/python bench/map_cpu.py [--seconds 8]

Writes bench/results/map_cpu.json and prints a table.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import queue
import socket
import threading
import time
from collections.abc import Iterator
from typing import Any

from common import free_port, latency_stats, write
from pythonosc.osc_message import OscMessage

from sonibus import schemas
from sonibus.adapters.map import MapConfig, MapNode
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import Bus, BusConfig, codec, framing, keys, load_model, open_session

RATE_HZ = 100.0
MAPS = 50
MODEL = load_model("pepper")
CURVES = ("linear", "exp", "log", "s")


def tables() -> dict[str, dict[str, Any]]:
    """The 50 maps: each on a joint (in turn), with a curve, and smoothing on most."""
    out = {}
    for i in range(MAPS):
        joint = MODEL.joints[i % len(MODEL.joints)]
        table: dict[str, Any] = {"source": keys.joint("pepper", joint.name), "to": [200, 2000], "unit": "Hz",
                                 "curve": CURVES[i % len(CURVES)]}
        if i % 2 == 0:
            table["smooth_ms"] = 80
        elif i % 4 == 1:
            table["one_euro"] = {"min_cutoff": 1.0, "beta": 0.01}
        if i % 10 == 0:
            table["threshold"] = [1500, 1000]
        out[f"m{i}"] = table
    return out


class Robot:
    """A Pepper's info and its frames at 100 Hz on one session, until stopped."""

    def __init__(self, bus: Bus) -> None:
        info = {"robot": "pepper", "model": "pepper", "joints": [j.to_info() for j in MODEL.joints],
                "rate_hz": RATE_HZ, "behaviors": [], "postures": [], "adapter": "bench",
                "schema_version": schemas.VERSION, "owner": {"host": bus.host, "node": "bench"}}
        payload = codec.encode(info)
        self.queryable = bus.session.declare_queryable(
            keys.info("pepper"), lambda q: q.reply(keys.info("pepper"), payload, encoding=codec.ENCODING))
        self.publisher = bus.session.declare_publisher(keys.frame("pepper"))
        self.names = [j.name for j in MODEL.joints]
        self.middle = [(j.min + j.max) / 2 for j in MODEL.joints]
        self.half = [(j.max - j.min) / 2 for j in MODEL.joints]
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        start = time.monotonic()
        while not self.stop.is_set():
            t = time.time()
            values = [m + 0.5 * h * math.sin(2 * math.pi * 0.5 * (t - start) + k)
                      for k, (m, h) in enumerate(zip(self.middle, self.half, strict=True))]
            self.publisher.put(codec.encode(framing.frame(t, self.sent, self.names, values)))
            self.sent += 1
            self.stop.wait(max(0.0, start + self.sent / RATE_HZ - time.monotonic()))

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.publisher.undeclare()
        self.queryable.undeclare()


def thread_cpu(name: str, seconds: float, count: Any) -> dict[str, float]:
    """CPU % of one core of the thread called ``name`` over ``seconds``, and what ``count()`` grew by."""
    thread = next(t for t in threading.enumerate() if t.name == name)
    clock = time.pthread_getcpuclockid(thread.ident)
    cpu0, wall0, n0 = time.clock_gettime(clock), time.monotonic(), count()
    time.sleep(seconds)
    cpu, wall, n = time.clock_gettime(clock) - cpu0, time.monotonic() - wall0, count() - n0
    return {"seconds": round(wall, 3), "outputs_per_s": round(n / wall, 1), "cpu_percent": round(100 * cpu / wall, 2),
            "cpu_us_per_frame": round(1e6 * cpu / max(n / MAPS, 1), 1)}


@contextlib.contextmanager
def running(bus: Bus) -> Iterator[MapNode]:
    """The map node of the 50 maps on ``bus``, once it has sent 10 frames' outputs; stopped at the end."""
    node = MapNode(MapConfig(maps=tables()), name="sound")
    node.start(bus)
    try:
        deadline = time.monotonic() + 10
        while node.stats["sent"] < 10 * MAPS:
            if time.monotonic() > deadline:
                raise SystemExit(f"the map node sent {node.stats['sent']} outputs in 10 s: {dict(node.stats)}")
            time.sleep(0.05)
        yield node
    finally:
        node.stop()


def map_node(bus: Bus, seconds: float) -> dict[str, float]:
    with running(bus) as node:
        return thread_cpu("sound:map", seconds, lambda: node.stats["sent"])


def harness(bus: Bus, seconds: float) -> dict[str, float]:
    """The same arithmetic by hand: fraction of the joint's range, curve, 200..2000, one-pole."""
    spans = [(j.min, j.max) for j in MODEL.joints]
    curves = [lambda x: x, lambda x: (10 ** x - 1) / 9, lambda x: math.log1p(9 * x) / math.log(10),
              lambda x: x * x * (3 - 2 * x)]
    plan = [(i % len(spans), curves[i % 4], i % 2 == 0) for i in range(MAPS)]
    publishers = [bus.session.declare_publisher(f"hand/derived/map/m{i}") for i in range(MAPS)]
    frames: queue.Queue = queue.Queue(maxsize=8192)
    subscriber = bus.session.declare_subscriber(keys.frame("pepper"), lambda s: frames.put(s.payload.to_bytes()))
    stop, sent = threading.Event(), [0]
    state: list[float | None] = [None] * MAPS
    last_t = [0.0]

    def run() -> None:
        while not stop.is_set():
            try:
                payload = frames.get(timeout=0.2)
            except queue.Empty:
                continue
            frame = codec.decode(payload)
            t, v = frame["t"], frame["v"]
            a = -math.expm1(-(t - last_t[0]) / 0.080) if last_t[0] else 1.0
            last_t[0] = t
            for i, (joint, curve, smooth) in enumerate(plan):
                low, high = spans[joint]
                x = min(1.0, max(0.0, (v[joint] - low) / (high - low)))
                y = 200 + 1800 * curve(x)
                if smooth:
                    y = y if state[i] is None else state[i] + a * (y - state[i])
                    state[i] = y
                publishers[i].put(codec.encode({"t": t, "seq": frame["seq"], "v": y}))
                sent[0] += 1

    worker = threading.Thread(target=run, name="harness", daemon=True)
    worker.start()
    try:
        time.sleep(1.0)
        return thread_cpu("harness", seconds, lambda: sent[0])
    finally:
        stop.set()
        worker.join()
        subscriber.undeclare()
        for publisher in publishers:
            publisher.undeclare()


class Receiver:
    """A UDP socket keeping (arrival time, ``t`` sent with the value) of every OSC message."""

    def __init__(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.bind(("127.0.0.1", 0))
        self.socket.settimeout(0.1)
        self.target = f"127.0.0.1:{self.socket.getsockname()[1]}"
        self.latencies: list[float] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            try:
                data = self.socket.recv(65536)
            except TimeoutError:
                continue
            arrived = time.time()
            self.latencies.append(arrived - OscMessage(data).params[-1])

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.socket.close()


def latency(bus: Bus, seconds: float) -> dict[str, Any]:
    """Source to OSC: the robot's ``t`` to a UDP socket, for HeadYaw straight through an OSC
    sink, and for a map of HeadYaw (exp curve, one-pole) through the map node and an OSC sink."""
    direct, mapped = Receiver(), Receiver()
    node = MapNode(MapConfig(maps={"yaw": {"source": "pepper/joints/HeadYaw", "to": [200, 2000], "curve": "exp",
                                           "smooth_ms": 80}}), name="sound")
    sinks = [OscSink(OscSinkConfig(subscribe=("pepper/joints/HeadYaw",), targets=(direct.target,), extra=("t",)),
                     name="plain"),
             OscSink(OscSinkConfig(subscribe=("sound/derived/**",), targets=(mapped.target,), extra=("t",)),
                     name="mapped")]
    try:
        for adapter in (node, *sinks):
            adapter.start(bus)
        time.sleep(1.0)
        direct.latencies.clear()
        mapped.latencies.clear()
        time.sleep(seconds)
    finally:
        for adapter in (*sinks, node):
            adapter.stop()
        direct.close()
        mapped.close()
    plain, through = latency_stats(direct.latencies), latency_stats(mapped.latencies)
    return {"plain_osc_sink": plain, "through_map_node": through,
            "ratio_p50": round(through["p50_us"] / plain["p50_us"], 2)}


@contextlib.contextmanager
def stage() -> Iterator[tuple[Any, Any]]:
    """Two sessions over loopback, the robot's (listening; its frames at 100 Hz on it) and
    the node's (connected to it), closed at the end."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot_session = open_session(BusConfig(multicast=False, listen=(endpoint,)))
    node_session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    robot = Robot(Bus(robot_session, node="robot"))
    try:
        yield robot_session, node_session
    finally:
        robot.close()
        node_session.close()
        robot_session.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    with stage() as (_, node_session):
        node = map_node(Bus(node_session), args.seconds)
        plain = harness(Bus(node_session, node="harness"), args.seconds)
        path = latency(Bus(node_session), args.seconds / 2)
    result = {"maps": MAPS, "rate_hz": RATE_HZ, "machine": machine, "map_node": node, "harness": plain,
              "ratio_cpu": round(node["cpu_percent"] / max(plain["cpu_percent"], 1e-9), 2), "latency": path}
    result["summary"] = [{"scenario": "map node: 50 maps on a Pepper at 100 Hz, CPU of its worker",
                          "sonibus": f"{node['cpu_percent']:.1f} % of a core ({node['cpu_us_per_frame']:.0f} µs/frame)",
                          "baseline": f"{plain['cpu_percent']:.1f} % (hand-written loop, same arithmetic)",
                          "ratio": f"{result['ratio_cpu']:.1f}×", "goal": "", "met": ""},
                         {"scenario": "source to OSC through a map (HeadYaw, exp, one-pole), p50 / p99",
                          "sonibus": f"{path['through_map_node']['p50_us']:,.0f} / "
                                     f"{path['through_map_node']['p99_us']:,.0f} µs",
                          "baseline": f"{path['plain_osc_sink']['p50_us']:,.0f} / "
                                      f"{path['plain_osc_sink']['p99_us']:,.0f} µs (HeadYaw to the OSC sink)",
                          "ratio": f"{path['ratio_p50']:.1f}×", "goal": "", "met": ""}]
    print(f"{'50 maps @100 Hz':<16} {'outputs/s':>10} {'CPU % core':>11} {'µs/frame':>9}")
    for name, row in (("map node", node), ("harness", plain)):
        print(f"{name:<16} {row['outputs_per_s']:>10.0f} {row['cpu_percent']:>11.2f} {row['cpu_us_per_frame']:>9.0f}")
    print(f"ratio {result['ratio_cpu']:.2f}")
    for name, row in (("plain OSC sink", path["plain_osc_sink"]), ("through the map", path["through_map_node"])):
        print(f"source → OSC, {name:<16} p50 {row['p50_us']:>7.0f} µs  p99 {row['p99_us']:>7.0f} µs  n {row['n']}")
    write("map_cpu", result)
    print(machine)


if __name__ == "__main__":
    main()
