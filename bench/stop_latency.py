"""Time from ``stop`` sent to the simulated robot halting, beside the round trip
of a command that does nothing (issue 9, scenario f).

A simulated Pepper (``sim`` adapter, 100 frames/s) runs in its own process
(``sonibus run``, listening on loopback TCP); this process is the commander.
Each trial turns HeadYaw towards the far end of its range at full speed
(``joints/set``, speed 1.0), waits until the HeadYaw samples show it moving,
waits a random 0..1 frame more (a stop comes at any phase of the robot's frame
loop), then sends ``stop`` and measures:

- stop round trip: ``send_command(stop)`` until its reply is back;
- halted (robot): from sending ``stop`` to the ``t`` of the first frame whose
  HeadYaw equals the previous frame's (the robot's acquisition clock and ours
  are the same host's wall clock);
- halted (seen): from sending ``stop`` to that frame's arrival here.

Baseline, same run, each trial: the round trip of ``behavior/list`` (validated
and answered, moves nothing). Goal (issue 9): stop reaches the robot within
50 ms p99.

    .venv/bin/python bench/stop_latency.py [--trials 500] [--rate 100]

Writes bench/results/stop_latency.json and prints a table.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from common import free_port, latency_stats, write
from sink_throughput import SONIBUS, cpu_seconds, stop_process

JOINT = "HeadYaw"
FAR = 2.0  # rad; HeadYaw's limits are ±2.0857, its top speed 7.34 rad/s: ≥ 0.27 s of motion


class Follower:
    """HeadYaw samples as (t, seq, value, arrival monotonic s), read from a subscription."""

    def __init__(self, bus: Any) -> None:
        from sonibus.bus import codec
        self.decode = codec.decode
        self.subscriber, self.queue = bus.subscribe(f"pepper/joints/{JOINT}", maxlen=100_000, stamped=True)
        self.last: tuple[float, int, float, float] | None = None

    def next(self, timeout: float = 2.0) -> tuple[float, int, float, float]:
        item = self.queue.get(timeout=timeout)
        if item is None:
            raise RuntimeError(f"no pepper/joints/{JOINT} sample within {timeout:g} s")
        message = self.decode(item[1])
        self.last = (message["t"], message["seq"], message["v"], item[2] / 1e9)
        return self.last

    def drain(self) -> tuple[float, int, float, float]:
        """The newest sample (waiting for one if none is queued)."""
        while len(self.queue):
            self.next()
        return self.last if self.last is not None else self.next()


def trial(bus: Any, follower: Follower, rng: random.Random, period: float) -> dict[str, float]:
    from sonibus.bus import send_command

    _, _, position, _ = follower.drain()
    started = time.perf_counter()
    send_command(bus, "pepper", "joints/set", {"names": [JOINT], "angles": [-FAR if position > 0 else FAR],
                                               "speed": 1.0})
    set_rtt = time.perf_counter() - started
    previous = follower.next()
    while True:  # moving: two consecutive frames differ
        sample = follower.next()
        if sample[2] != previous[2]:
            break
        previous = sample
    time.sleep(rng.uniform(0.0, period))
    previous = follower.drain()
    sent_wall, sent_mono = time.time(), time.monotonic()
    send_command(bus, "pepper", "stop")
    stop_rtt = time.monotonic() - sent_mono
    while True:  # halted: a frame equal to the one before it
        sample = follower.next()
        if sample[2] == previous[2] and sample[1] > previous[1]:
            break
        previous = sample
    halted, seen = sample[0] - sent_wall, sample[3] - sent_mono
    started = time.perf_counter()
    send_command(bus, "pepper", "behavior/list")
    list_rtt = time.perf_counter() - started
    return {"stop_rtt": stop_rtt, "halted": halted, "seen": seen, "list_rtt": list_rtt, "set_rtt": set_rtt}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--rate", type=float, default=100.0, help="the simulator's frames/s")
    parser.add_argument("--seed", type=int, default=9)
    args = parser.parse_args()
    from sonibus.bus import Bus, BusConfig, open_session, robot_info

    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    rng = random.Random(args.seed)
    trials: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "robot.toml"
        config.write_text(f'[bus]\nmulticast = false\n\n[nodes.robot]\nadapter = "sim"\nrobot = "pepper"\n'
                          f'rate_hz = {args.rate:g}\n')
        robot = subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--listen", endpoint],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                 start_new_session=True)
        session = None
        try:
            session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
            bus = Bus(session, node="bench-commander")
            deadline = time.monotonic() + 30
            while robot_info(bus, "pepper", timeout=0.5) is None:
                if robot.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the simulated robot did not come up: {robot.stderr.read()[-1000:]}")
            follower = Follower(bus)
            for _ in range(3):  # warm up: sessions, routes, caches
                trial(bus, follower, rng, 1.0 / args.rate)
            cpu0, started = cpu_seconds(robot.pid), time.monotonic()
            for _ in range(args.trials):
                trials.append(trial(bus, follower, rng, 1.0 / args.rate))
            robot_cpu = 100.0 * (cpu_seconds(robot.pid) - cpu0) / (time.monotonic() - started)
            follower.subscriber.undeclare()
        finally:
            if session is not None:
                session.close()
            stop_process(robot)
    rows = {name: latency_stats([t[name] for t in trials]) for name in ("list_rtt", "stop_rtt", "set_rtt", "halted",
                                                                        "seen")}
    result = {"trials": args.trials, "rate_hz": args.rate, "machine": machine, "robot_cpu_percent": robot_cpu,
              "baseline_behavior_list_rtt": rows["list_rtt"], "stop_rtt": rows["stop_rtt"],
              "joints_set_rtt": rows["set_rtt"], "halted_robot_t": rows["halted"], "halted_seen": rows["seen"]}
    for name in ("stop_rtt", "halted_robot_t"):
        result[f"ratio_{name}_p50"] = result[name]["p50_us"] / rows["list_rtt"]["p50_us"]
        result[f"ratio_{name}_p99"] = result[name]["p99_us"] / rows["list_rtt"]["p99_us"]
    halted, stop, base = rows["halted"], rows["stop_rtt"], rows["list_rtt"]
    result["summary"] = [  # the rows of bench/run.py's table
        {"scenario": "(f) stop sent → robot halted (frame t), p50 / p99",
         "sonibus": f"{halted['p50_us'] / 1000:.1f} / {halted['p99_us'] / 1000:.1f} ms",
         "baseline": f"{base['p50_us'] / 1000:.1f} / {base['p99_us'] / 1000:.1f} ms (behavior/list round trip)",
         "ratio": f"{halted['p50_us'] / base['p50_us']:.1f}× / {halted['p99_us'] / base['p99_us']:.1f}×",
         "goal": "p99 ≤ 50 ms", "met": "yes" if halted["p99_us"] <= 50_000 else "no"},
        {"scenario": "(f) stop round trip, p50 / p99",
         "sonibus": f"{stop['p50_us'] / 1000:.1f} / {stop['p99_us'] / 1000:.1f} ms",
         "baseline": f"{base['p50_us'] / 1000:.1f} / {base['p99_us'] / 1000:.1f} ms (behavior/list)",
         "ratio": f"{stop['p50_us'] / base['p50_us']:.1f}× / {stop['p99_us'] / base['p99_us']:.1f}×"}]
    print(f"{'µs, ' + str(args.trials) + ' trials':<34} {'p50':>7} {'p99':>7} {'max':>7} {'× list p50':>10}")
    for label, key in (("behavior/list round trip (base)", "list_rtt"), ("stop round trip", "stop_rtt"),
                       ("joints/set round trip", "set_rtt"), ("stop sent → halted frame's t", "halted"),
                       ("stop sent → halted frame here", "seen")):
        r = rows[key]
        print(f"{label:<34} {r['p50_us']:>7.0f} {r['p99_us']:>7.0f} {r['max_us']:>7.0f} "
              f"{r['p50_us'] / rows['list_rtt']['p50_us']:>10.2f}")
    goal = "met" if rows["halted"]["p99_us"] <= 50_000 else "not met"
    print(f"goal: halted within 50 ms p99 — {goal} ({rows['halted']['p99_us'] / 1000:.1f} ms; one frame is "
          f"{1000 / args.rate:g} ms); robot process {robot_cpu:.0f} % CPU")
    write("stop_latency", result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
