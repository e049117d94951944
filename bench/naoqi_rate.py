"""Joint acquisition from NAOqi: the naoqi adapter's achieved frame rate and
jitter beside PepperOSC's way of reading, against the fake NAOqi endpoint.

The fake runs in its own process (a real libqi server, every call delayed by
``delay_ms`` like a network), the reader in this one:

- sonibus: the ``naoqi`` adapter (one ``ALMemory.getListData`` of all 17
  positions per frame, paced by ``Pacer``), at 100 frames/s and as fast as it
  goes (``rate_hz = 1000``); frame times are the samples' ``t`` on the bus.
- PepperOSC: a fresh ``session.service("ALMemory")`` proxy every loop, then one
  ``getData`` per joint; at 100 loops/s (paced the same way) and unpaced.

Jitter is |Δt − median Δt| between consecutive frames.

    .venv/bin/python bench/naoqi_rate.py [--seconds 5] [--delays 0 2]

Writes bench/results/naoqi_rate.json and prints a table.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
from common import free_port

ROOT = Path(__file__).resolve().parent
POSITION = "Device/SubDeviceList/{}/Position/Sensor/Value"
FAST_HZ = 1000.0  # the adapter's highest rate: the pacer then never waits


def serve_fake(url: str, delay_ms: float, ready: multiprocessing.Event, stop: multiprocessing.Event) -> None:
    from sonibus.adapters.sim.naoqi import FakeNaoqi, FakeNaoqiConfig
    fake = FakeNaoqi(FakeNaoqiConfig(listen=url, model="pepper", rate_hz=100, delay_ms=delay_ms)).start()
    ready.set()
    stop.wait()
    fake.stop()
    fake.services.clear()  # else libqi aborts this process at exit (SIGABRT, "terminate called ...")


def summarize(times: list[float], reads: list[float]) -> dict[str, float]:
    """Frame rate and jitter from frame times (s), read latency from read times (s)."""
    t = np.array(times)
    intervals = np.diff(t)
    jitter = np.abs(intervals - np.median(intervals)) * 1e3
    read = np.array(reads) * 1e3
    return {"frames": len(t), "rate_hz": float((len(t) - 1) / (t[-1] - t[0])),
            "interval_p50_ms": float(np.median(intervals) * 1e3),
            "jitter_p50_ms": float(np.percentile(jitter, 50)), "jitter_p99_ms": float(np.percentile(jitter, 99)),
            "read_p50_ms": float(np.percentile(read, 50)), "read_p99_ms": float(np.percentile(read, 99))}


def adapter_run(url: str, rate_hz: float, seconds: float) -> dict[str, float]:
    from sonibus.adapters.naoqi import NaoqiConfig, NaoqiRobot
    from sonibus.bus import Bus, BusConfig, decode, open_session

    session = open_session(BusConfig(multicast=False))
    bus = Bus(session, node="bench")
    subscriber, queue = bus.subscribe("pepper/joints/HeadYaw", maxlen=1_000_000)
    robot = NaoqiRobot(NaoqiConfig(robot="pepper", url=url, rate_hz=rate_hz), name="naoqi-bench")
    robot.start(bus)
    try:
        while queue.get(timeout=5.0) is None:
            pass
        while queue.get(timeout=0) is not None:  # start measuring from now
            pass
        end = time.monotonic() + seconds
        times: list[float] = []
        while time.monotonic() < end:
            item = queue.get(timeout=0.5)
            if item is not None:
                times.append(decode(item[1])["t"])
        reads = robot.read_times.reads()  # the adapter's own, over its last few seconds
    finally:
        robot.stop()
        subscriber.undeclare()
        session.close()
    return summarize(times, reads)


def pepperosc_run(url: str, rate_hz: float | None, seconds: float) -> dict[str, float]:
    """PepperOSC's loop: a new ALMemory proxy, then one getData per joint, every loop."""
    import qi

    from sonibus.bus.pacing import Pacer
    from sonibus.bus.robot import load_model

    session = qi.Session()
    session.connect(url)
    keys = [POSITION.format(j) for j in load_model("pepper").joint_names]
    times: list[float] = []
    reads: list[float] = []
    stop = threading.Event()
    end = time.monotonic() + seconds

    def loop(_: int) -> None:
        started, wall = time.monotonic(), time.time()
        memory = session.service("ALMemory")
        [memory.getData(k) for k in keys]
        read = time.monotonic() - started
        times.append(wall + read / 2)
        reads.append(read)
        if time.monotonic() >= end:
            stop.set()

    if rate_hz is None:
        while not stop.is_set():
            loop(0)
    else:
        Pacer(rate_hz).run(loop, stop)
    session.close()
    return summarize(times, reads)


def measure(delay_ms: float, seconds: float) -> dict[str, dict[str, float]]:
    context = multiprocessing.get_context("spawn")
    ready, stop = context.Event(), context.Event()
    url = f"tcp://127.0.0.1:{free_port()}"
    fake = context.Process(target=serve_fake, args=(url, delay_ms, ready, stop), daemon=True)
    fake.start()
    if not ready.wait(20):
        sys.exit("the fake NAOqi endpoint did not start")
    try:
        return {"sonibus_100hz": adapter_run(url, 100.0, seconds),
                "sonibus_max": adapter_run(url, FAST_HZ, seconds),
                "pepperosc_100hz": pepperosc_run(url, 100.0, seconds),
                "pepperosc_max": pepperosc_run(url, None, seconds)}
    finally:
        stop.set()
        fake.join(5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--delays", type=float, nargs="+", default=[0.0, 2.0])
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    runs = {f"delay_{d:g}ms": measure(d, args.seconds) for d in args.delays}
    result = {"joints": 17, "seconds": args.seconds, "machine": machine, "runs": runs}
    out = ROOT / "results" / "naoqi_rate.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"{'delay':<6} {'reader':<16} {'frames/s':>9} {'Δt p50 ms':>10} {'jitter p50':>11} {'jitter p99':>11} "
          f"{'read p50 ms':>12} {'read p99 ms':>12}")
    for delay, readers in runs.items():
        for name, r in readers.items():
            print(f"{delay[6:]:<6} {name:<16} {r['rate_hz']:>9.1f} {r['interval_p50_ms']:>10.2f} "
                  f"{r['jitter_p50_ms']:>11.3f} {r['jitter_p99_ms']:>11.3f} {r['read_p50_ms']:>12.2f} "
                  f"{r['read_p99_ms']:>12.2f}")
    print(f"({machine}; jitter = |Δt − median Δt| in ms)")


if __name__ == "__main__":
    main()
