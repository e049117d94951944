"""Cost of the features processor per Pepper frame at 100 Hz, beside a baseline.

- per frame, no bus: N synthetic Pepper frames (17 joints moving, 100 Hz, each
  one ``pepper/frame`` message as a robot owner puts it) go through what the
  processor does for each frame — decode the frame, compute every feature
  (velocity, hands, hand speeds, QoM, onsets), encode the derived frame it
  publishes — timed per frame, with the default features and with
  ``expressive`` added. Baselines: only decoding the frame; and ``before``, the
  default features as computed before issue 35's per-frame work (numpy on every
  step: ``tests/features/reference.py``, the step the tests hold the new one to).
  The four are timed in turn on each frame, so the machine's load weighs on each alike.
- instructions per frame: the same four, each on the same frames, counted by
  ``valgrind --tool=callgrind`` in one process (deterministic, whatever the load).
- on the bus: a simulated Pepper at 100 frames/s and three ``features`` nodes in
  this process, side by side over loopback: ``before`` (a default node computing
  with the reference step), ``default`` (a show's node), and one with
  ``expressive`` added; CPU time of each node's worker thread (it also takes the
  frame off the queue, checks it, and hands the derived frame to Zenoh) over the
  run, as % of one core, and their ratios (issue 36: expressive at most 1.5×).

    .venv/bin/python bench/features.py [--frames 20000] [--seconds 10] [--counted 200]

Writes bench/results/features.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from common import free_port, write

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.features.compute import Output, RobotFeatures
from sonibus.adapters.features.config import DEFAULT
from sonibus.adapters.features.processor import derived_frame, whole
from sonibus.adapters.features.table import describe
from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import Bus, BusConfig, codec, framing, keys, load_model, open_session, robot_info, send_command
from sonibus.bus.streams import Selection

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the tests package, for the reference step
from tests.features.reference import ReferenceFeatures

RATE_HZ = 100.0
MODEL = load_model("pepper")
INFO = {"model": "pepper", "joints": [j.to_info() for j in MODEL.joints]}
VARIANTS = ("decode_only", "before", "features", "expressive")


class Before:
    """The default features as computed before issue 35 (``ReferenceFeatures``), giving what
    the processor publishes: the values' names cut from their keys as its ``derived_frame``
    then did."""

    def __init__(self) -> None:
        self.reference = ReferenceFeatures(describe("pepper", INFO), FeaturesConfig())
        self.frames = 0

    def step(self, t: float, seq: int, values: dict[str, Any]) -> Output:
        self.frames += 1
        out = self.reference.step(t, seq, values)
        cut = len(keys.derived_frame("pepper")) + 1
        return Output(t, seq, keys.derived_frame("pepper") + "/", [k[cut:] for k, _ in out.samples],
                      [m["v"] for _, m in out.samples], out.events)


def variants() -> dict[str, Callable[[bytes], Any]]:
    """Each variant as a call on one ``pepper/frame`` payload: what the processor does with it."""
    key, selection = keys.frame("pepper"), Selection([keys.joints("pepper")])
    robots = {"before": Before(), "features": RobotFeatures(describe("pepper", INFO), FeaturesConfig()),
              "expressive": RobotFeatures(describe("pepper", INFO), FeaturesConfig(features=(*DEFAULT, "expressive")))}

    def computed(robot: Any) -> Callable[[bytes], Any]:
        def call(payload: bytes) -> bytes:
            frame = whole(selection.incoming(key, payload))
            return derived_frame(robot.step(frame.t, frame.seq, frame.values))  # as the node publishes it
        return call

    return {"decode_only": lambda payload: selection.incoming(key, payload),
            **{name: computed(robot) for name, robot in robots.items()}}


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
        out.append(codec.encode(framing.frame(t, k, MODEL.joint_names, values.tolist())))
    return out


def per_frame(data: list[bytes]) -> dict[str, list[float]]:
    """Seconds per frame of each variant (decoding only, the default features before issue 35
    and now, with the opt-in expressive descriptors added): taken in turn on each frame, so
    that the machine's load weighs on each alike."""
    calls = variants()
    times: dict[str, list[float]] = {name: [] for name in calls}
    clock = time.perf_counter
    gc.disable()
    for payload in data:
        for name, call in calls.items():
            started = clock()
            call(payload)
            times[name].append(clock() - started)
    gc.enable()
    return {name: seconds[100:] for name, seconds in times.items()}  # warm caches first


def segments(n: int) -> None:
    """Under callgrind: each variant on ``n`` frames after ``n`` others, ``os.getppid``
    before each and at the end (callgrind dumps its counts there), the collector off."""
    calls, data = variants(), frames(2 * n)
    for call in calls.values():
        for payload in data[:n]:
            call(payload)
    gc.collect()
    gc.disable()
    for call in calls.values():
        os.getppid()
        for payload in data[n:]:
            call(payload)
    os.getppid()
    gc.enable()


def instructions(n: int) -> dict[str, float]:
    """Instructions per frame of each variant, counted in one process under callgrind."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                              "--dump-before=os_getppid", "--separate-threads=yes", sys.executable, __file__,
                              "--segments", str(n)], capture_output=True, text=True, cwd=Path(__file__).parent)
        if run.returncode:
            raise SystemExit(f"callgrind run failed:\n{run.stderr[-3000:]}")
        main = list(Path(tmp).glob("callgrind.out.*-01"))  # (the main thread's dumps)
        main.sort(key=lambda path: int(path.name.rsplit(".", 1)[1].split("-")[0]))
        totals = [int(re.search(r"^(?:summary|totals): (\d+)", path.read_text(), re.M).group(1)) for path in main]
    # dump 1 is the setup and warm-up; then one per variant, each ended by the next getppid
    return {name: total / n for name, total in zip(VARIANTS, totals[1:], strict=False)}


def stats(seconds: list[float]) -> dict[str, float]:
    a = np.array(seconds) * 1e6
    return {"frames": len(a), "p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "mean_us": float(a.mean()), "cpu_percent_at_100hz": float(a.mean() * RATE_HZ / 1e4)}


def on_bus(seconds: float) -> dict[str, dict[str, float]]:
    """The CPU time of three features nodes taking frames (decode, compute, publish):
    ``before`` (a default node computing with the step before issue 35), ``default`` (a
    show's) and ``expressive``, side by side on one bus while a simulated Pepper streams at
    100 Hz: all take the same frames under the same load. Counted in each node's ``_take``
    with its thread's CPU clock, on whichever thread took the frame: a frame is taken where
    it arrives, on Zenoh's callback threads, which the three nodes share (their worker
    threads, measured until 30 Nov, took none and read 0)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot_session = open_session(BusConfig(multicast=False, listen=(endpoint,)))
    node_session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    sim = SimRobot(SimConfig(robot="pepper", rate_hz=RATE_HZ, idle=True), name="sim-pepper")
    nodes = {"before": Features(FeaturesConfig(robots="pepper"), name="before"),
             "default": Features(FeaturesConfig(robots="pepper"), name="default"),
             "expressive": Features(FeaturesConfig(robots="pepper", features=(*DEFAULT, "expressive")),
                                    name="expressive")}
    spent = dict.fromkeys(nodes, 0)  # ns of CPU in each node's _take (under its state lock: one thread at a time)

    def timed(name: str, take: Callable[..., None]) -> Callable[..., None]:
        def counted(*args: Any) -> None:
            started = time.thread_time_ns()
            try:
                take(*args)
            finally:
                spent[name] += time.thread_time_ns() - started
        return counted

    try:
        sim.start(Bus(robot_session))
        for name, node in nodes.items():
            node._take = timed(name, node._take)  # type: ignore[method-assign]
            node.start(Bus(node_session))
        bus = Bus(node_session, node="bench")
        deadline = time.monotonic() + 30
        while robot_info(bus, "pepper", timeout=0.5) is None or any(
                "pepper" not in node.robot_features for node in nodes.values()):
            if time.monotonic() > deadline:
                raise TimeoutError("the features nodes did not learn the simulated Pepper in 30 s")
            time.sleep(0.05)
        nodes["before"].robot_features["pepper"] = Before()  # type: ignore[assignment]
        send_command(bus, "pepper", "behavior/run", {"name": "animations/Stand/Gestures/Enthusiastic_4"})
        time.sleep(1.0)  # the frames queued while the nodes learned the robot are behind them
        cpu0 = dict(spent)
        frames0 = {name: node.stats["frames"] for name, node in nodes.items()}
        wall0 = time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - wall0
        cpu = {name: (spent[name] - cpu0[name]) / 1e9 for name in nodes}
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
    parser.add_argument("--counted", type=int, default=200, help="frames counted by callgrind per variant (0: none)")
    parser.add_argument("--segments", type=int, help=argparse.SUPPRESS)  # (the run under callgrind)
    args = parser.parse_args()
    if args.segments:
        segments(args.segments)
        return
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    data = frames(args.frames + 100)
    timed = {name: stats(seconds) for name, seconds in per_frame(data).items()}
    base, before, full, expressive = (timed[name] for name in VARIANTS)
    counted = instructions(args.counted) if args.counted else {}
    nodes = on_bus(args.seconds)
    bus, bus_expressive = nodes["default"], nodes["expressive"]
    result = {"model": "pepper", "joints": len(MODEL.joints), "rate_hz": RATE_HZ, "machine": machine,
              "decode_only": base, "before": before, "features": full, "ratio_p50": full["p50_us"] / base["p50_us"],
              "ratio_p99": full["p99_us"] / base["p99_us"], "before_ratio_p50": before["p50_us"] / base["p50_us"],
              "after_to_before_p50": full["p50_us"] / before["p50_us"],
              "after_to_before_p99": full["p99_us"] / before["p99_us"],
              "instructions_per_frame": counted, "on_bus": bus, "on_bus_before": nodes["before"],
              "on_bus_after_to_before": bus["cpu_percent"] / nodes["before"]["cpu_percent"], "expressive": expressive,
              "expressive_ratio_p50": expressive["p50_us"] / full["p50_us"],
              "expressive_ratio_p99": expressive["p99_us"] / full["p99_us"],
              "expressive_ratio_mean": expressive["mean_us"] / full["mean_us"], "on_bus_expressive": bus_expressive,
              "on_bus_expressive_ratio": bus_expressive["cpu_percent"] / bus["cpu_percent"]}
    print(f"{'per frame':<12} {'p50 µs':>8} {'p99 µs':>8} {'CPU % @100 Hz':>14} {'instructions':>13}")
    for name, row in zip(("decode only", "before", "features", "+expressive"), (base, before, full, expressive),
                         strict=True):
        key = VARIANTS[(base, before, full, expressive).index(row)]
        count = f"{counted[key] / 1000:,.0f}k" if key in counted else ""
        print(f"{name:<12} {row['p50_us']:>8.0f} {row['p99_us']:>8.0f} {row['cpu_percent_at_100hz']:>14.2f} "
              f"{count:>13}")
    print(f"features / decode only: p50 {result['ratio_p50']:.1f}, p99 {result['ratio_p99']:.1f} "
          f"(before: p50 {result['before_ratio_p50']:.1f}); features / before: p50 "
          f"{result['after_to_before_p50']:.2f}, p99 {result['after_to_before_p99']:.2f}")
    if counted:
        print("instructions / decode only: " + ", ".join(f"{name} {counted[name] / counted['decode_only']:.1f}"
                                                       for name in VARIANTS[1:])
              + f"; features / before {counted['features'] / counted['before']:.2f}")
    print(f"+expressive / features: p50 {result['expressive_ratio_p50']:.2f}, "
          f"p99 {result['expressive_ratio_p99']:.2f}, "
          f"mean {result['expressive_ratio_mean']:.2f}")
    for name, row in nodes.items():
        print(f"on the bus, {name}: {row['frames_per_s']:.1f} frames/s, worker thread {row['cpu_percent']:.1f} % "
              f"of a core ({row['cpu_us_per_frame']:.0f} µs/frame)")
    print(f"on the bus, default / before: {result['on_bus_after_to_before']:.2f}; "
          f"+expressive / default: {result['on_bus_expressive_ratio']:.2f}")
    write("features", result)
    print(machine)


if __name__ == "__main__":
    main()
