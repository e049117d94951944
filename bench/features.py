"""Cost of the features processor per Pepper frame at 100 Hz, beside a baseline.

- per frame, no bus: N synthetic Pepper frames (17 joints moving, 100 Hz, each
  one ``pepper/frame`` message as a robot owner puts it) go through what the
  processor does for each frame — decode the frame, compute every feature
  (velocity, hands, hand speeds, QoM, onsets), encode the derived frame it
  publishes — timed per frame, with the default features and with
  ``expressive`` added. Baseline: only decoding the frame. The three are timed
  in turn on each frame, so the machine's load weighs on each alike.
- on the bus: a simulated Pepper at 100 frames/s and two ``features`` nodes in
  this process, one with the default features (a show's node), one with
  ``expressive`` added, side by side over loopback; CPU time of each node's
  worker thread (it also hands the derived frame to Zenoh) over the run, as %
  of one core, and their ratio (issue 36: at most 1.5).

    .venv/bin/python bench/features.py [--frames 20000] [--seconds 10]

Writes bench/results/features.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import os
import threading
import time

import numpy as np
from common import free_port, write

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.config import DEFAULT
from sonibus.adapters.features.processor import derived_frame, whole
from sonibus.adapters.features.table import describe
from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import Bus, BusConfig, codec, keys, load_model, messages, open_session, robot_info, send_command
from sonibus.bus.streams import Selection

RATE_HZ = 100.0
MODEL = load_model("pepper")


def frames(n: int) -> list[bytes]:
    """``n`` encoded frames (``pepper/frame``): every joint swinging around the middle of its range."""
    t0 = time.time() - n / RATE_HZ - 10  # every t in the past (the gate refuses t ahead of the clock)
    middle = np.array([(j.min + j.max) / 2 for j in MODEL.joints])
    half = np.array([(j.max - j.min) / 2 for j in MODEL.joints])
    phase = np.arange(len(MODEL.joints))
    out = []
    for k in range(n):
        t = t0 + k / RATE_HZ
        values = middle + 0.3 * half * np.sin(2 * np.pi * 0.5 * (t - t0) + phase)
        out.append(codec.encode(messages.frame(t, k, MODEL.joint_names, values.tolist())))
    return out


def per_frame(data: list[bytes]) -> dict[str, list[float]]:
    """Seconds per frame of decoding only, of the processor's whole per-frame work with the
    default features, and with the opt-in expressive descriptors added: the three taken in
    turn on each frame, so that the machine's load weighs on each alike."""
    info = {"model": "pepper", "joints": [j.to_info() for j in MODEL.joints]}
    robots = {"features": RobotFeatures(describe("pepper", info), FeaturesConfig()),
              "expressive": RobotFeatures(describe("pepper", info), FeaturesConfig(features=(*DEFAULT, "expressive")))}
    key, selection = keys.frame("pepper"), Selection([keys.joints("pepper")])
    times: dict[str, list[float]] = {"decode_only": [], **{name: [] for name in robots}}
    clock = time.perf_counter
    gc.disable()
    for payload in data:
        started = clock()
        selection.incoming(key, payload)
        times["decode_only"].append(clock() - started)
        for name, robot in robots.items():
            started = clock()
            frame = whole(selection.incoming(key, payload))
            derived_frame(robot.step(frame.t, frame.seq, frame.values))  # as the node publishes it
            times[name].append(clock() - started)
    gc.enable()
    return {name: seconds[100:] for name, seconds in times.items()}  # warm caches first


def stats(seconds: list[float]) -> dict[str, float]:
    a = np.array(seconds) * 1e6
    return {"frames": len(a), "p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "mean_us": float(a.mean()), "cpu_percent_at_100hz": float(a.mean() * RATE_HZ / 1e4)}


def on_bus(seconds: float) -> dict[str, dict[str, float]]:
    """The CPU time of two features nodes' worker threads, one with the default features (a
    show's), one with ``expressive`` added, side by side on one bus while a simulated Pepper
    streams at 100 Hz: both take the same frames under the same load."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot_session = open_session(BusConfig(multicast=False, listen=(endpoint,)))
    node_session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    sim = SimRobot(SimConfig(robot="pepper", rate_hz=RATE_HZ, idle=True), name="sim-pepper")
    nodes = {"default": Features(FeaturesConfig(robots="pepper"), name="default"),
             "expressive": Features(FeaturesConfig(robots="pepper", features=(*DEFAULT, "expressive")),
                                    name="expressive")}
    try:
        sim.start(Bus(robot_session))
        for node in nodes.values():
            node.start(Bus(node_session))
        bus = Bus(node_session, node="bench")
        deadline = time.monotonic() + 30
        while robot_info(bus, "pepper", timeout=0.5) is None or any(
                "pepper" not in node.robot_features for node in nodes.values()):
            if time.monotonic() > deadline:
                raise TimeoutError("the features nodes did not learn the simulated Pepper in 30 s")
            time.sleep(0.05)
        send_command(bus, "pepper", "behavior/run", {"name": "animations/Stand/Gestures/Enthusiastic_4"})
        time.sleep(1.0)  # the frames queued while the nodes learned the robot are behind them
        threads = {t.name: t for t in threading.enumerate()}
        clocks = {name: time.pthread_getcpuclockid(threads[f"{name}:features"].ident) for name in nodes}  # decode,
        cpu0 = {name: time.clock_gettime(clock) for name, clock in clocks.items()}          # compute, publish
        frames0 = {name: node.stats["frames"] for name, node in nodes.items()}
        wall0 = time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - wall0
        cpu = {name: time.clock_gettime(clock) - cpu0[name] for name, clock in clocks.items()}
        done = {name: node.stats["frames"] - frames0[name] for name, node in nodes.items()}
    finally:
        for node in nodes.values():
            node.stop()
        sim.stop()
        node_session.close()
        robot_session.close()
    return {name: {"seconds": wall, "frames": done[name], "frames_per_s": done[name] / wall,
                   "cpu_percent": 100 * cpu[name] / wall, "cpu_us_per_frame": 1e6 * cpu[name] / max(done[name], 1)}
            for name in nodes}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20_000)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    data = frames(args.frames + 100)
    timed = per_frame(data)
    base, full, expressive = (stats(timed[name]) for name in ("decode_only", "features", "expressive"))
    nodes = on_bus(args.seconds)
    bus, bus_expressive = nodes["default"], nodes["expressive"]
    result = {"model": "pepper", "joints": len(MODEL.joints), "rate_hz": RATE_HZ, "machine": machine,
              "decode_only": base, "features": full, "ratio_p50": full["p50_us"] / base["p50_us"],
              "ratio_p99": full["p99_us"] / base["p99_us"], "on_bus": bus, "expressive": expressive,
              "expressive_ratio_p50": expressive["p50_us"] / full["p50_us"],
              "expressive_ratio_p99": expressive["p99_us"] / full["p99_us"],
              "expressive_ratio_mean": expressive["mean_us"] / full["mean_us"], "on_bus_expressive": bus_expressive,
              "on_bus_expressive_ratio": bus_expressive["cpu_percent"] / bus["cpu_percent"]}
    print(f"{'per frame':<12} {'p50 µs':>8} {'p99 µs':>8} {'CPU % @100 Hz':>14}")
    for name, row in (("decode only", base), ("features", full), ("+expressive", expressive)):
        print(f"{name:<12} {row['p50_us']:>8.0f} {row['p99_us']:>8.0f} {row['cpu_percent_at_100hz']:>14.2f}")
    print(f"ratio p50 {result['ratio_p50']:.1f}, p99 {result['ratio_p99']:.1f}")
    print(f"+expressive / features: p50 {result['expressive_ratio_p50']:.2f}, "
          f"p99 {result['expressive_ratio_p99']:.2f}, "
          f"mean {result['expressive_ratio_mean']:.2f}")
    for name, row in (("default", bus), ("+expressive", bus_expressive)):
        print(f"on the bus, {name}: {row['frames_per_s']:.1f} frames/s, worker thread {row['cpu_percent']:.1f} % "
              f"of a core ({row['cpu_us_per_frame']:.0f} µs/frame)")
    print(f"on the bus, +expressive / default: {result['on_bus_expressive_ratio']:.2f}")
    write("features", result)
    print(machine)


if __name__ == "__main__":
    main()
