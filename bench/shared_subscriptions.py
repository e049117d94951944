"""Subscriptions of one process to one key: a Zenoh subscriber each, or one shared
(issue 35, ``bus/fanout.py``). What a process pays when N of its nodes take the same
robot's frames.

A publisher process puts Pepper-sized frames (a msgpack ``<robot>/frame`` of 17
joints, ~400 bytes) on ``pepper/frame`` at 50 and 100 frames/s. The receiving
process makes N subscriptions (1, 4, 8) to that key with ``Bus.subscribe``, each
into its own queue drained by a worker thread of its own (as a node's): either

- ``separate``: each from a ``Bus`` of its own on the process's one session (no
  sharing: N Zenoh subscribers, each with zenoh-python's channel and thread), as
  before sharing; or
- ``shared``: each from ``Bus.for_node`` of one ``Bus`` (as ``sonibus run`` gives its
  nodes): one Zenoh subscriber for the N, its callback on a Python thread of
  zenoh-python's own woken for each sample (``Callback(f, indirect=True)``, the default); or
- ``direct`` (``--ways shared direct``): shared, its callback called on Zenoh's own thread
  (``indirect=False``): no Python thread woken a sample, but Zenoh's thread attached to
  Python at each call (tried for issue 35 and left: docs/performance.md); or
- ``apart`` and ``broader`` (``--ways apart broader``): shared, the first half of the N
  subscriptions to ``pepper/frame`` (a robot's nodes: the OSC sink, features), the rest to
  ``*/frame`` (the recorder, Foxglove...), in that order: ``apart`` as a process without a
  plan (two Zenoh subscribers: the broader one came after), ``broader`` with ``*/frame``
  planned first, as ``sonibus run`` does (one: the robot's served by the broader one's).

The same code both ways. The two receiving processes run side by side, fed the same
frames by one publisher over the same window (a shared machine's load weighs on both
alike); each one's CPU from ``/proc/<pid>/task/*/schedstat`` over the window after a
warm-up; medians of rounds; every frame counted by every subscription.

    .venv/bin/python bench/shared_subscriptions.py [--rounds 3] [--seconds 5] [--name shared_subscriptions]

Writes bench/results/<name>.json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from typing import Any

from common import free_port, write, zenoh_config
from floor import CONTEXT, cpu_ns, switches

KEY = "pepper/frame"
EVERY = "*/frame"
WARMUP_S = 1.5
COUNTS = (1, 4, 8)
RATES = (50, 100)
WAYS = ("separate", "shared")


def frame(seq: int) -> bytes:
    """A Pepper-shaped frame: 17 joints' positions."""
    import msgpack
    names = [f"Joint{n:02d}" for n in range(17)]
    return msgpack.packb({"t": time.time(), "seq": seq, "names": names, "values": [0.1 * n for n in range(17)]})


def receiver(endpoint: str, count: int, way: str, ready: Any, done: Any, out: Any) -> None:
    """``count`` subscriptions to ``KEY``, each drained by a thread; reports frames taken and
    Zenoh subscribers declared when ``done``."""
    import threading

    from sonibus.bus import Bus, BusConfig, open_session
    session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    first = Bus(session, node="bench")
    if way == "direct":  # (called on Zenoh's thread, not on zenoh-python's thread woken a sample)
        import zenoh

        from sonibus.bus.fanout import Fanout
        first._subscriptions = Fanout(lambda keyexpr, callback: session.declare_subscriber(
            keyexpr, zenoh.handlers.Callback(callback, indirect=False)))
    buses = [Bus(session, node=f"n{n}") if way == "separate" else first.for_node(f"n{n}") for n in range(count)]
    if way == "broader":
        first.plan([EVERY])
    split = way in ("apart", "broader")  # (the first half a robot's subscriptions, the rest every robot's)
    taken = [0] * count
    subscriptions = []

    def drain(index: int, queue: Any) -> None:
        while not done.is_set():
            if queue.get(timeout=0.2) is not None:
                taken[index] += 1

    threads = []
    for index, bus in enumerate(buses):
        subscription, queue = bus.subscribe(EVERY if split and index >= count // 2 else KEY)
        subscriptions.append(subscription)
        threads.append(threading.Thread(target=drain, args=(index, queue), daemon=True))
        threads[-1].start()
    declared = sum(fanout.declared for fanout in {id(b._subscriptions): b._subscriptions for b in buses}.values())
    ready.set()
    done.wait()
    for thread in threads:
        thread.join(2)
    for subscription in subscriptions:
        subscription.undeclare()
    session.close()
    out.put({"taken": taken, "declared": declared})


def measure(count: int, rate: int, seconds: float, kinds: tuple[str, ...] = WAYS) -> dict[str, dict[str, Any]]:
    """Both ways side by side, fed the same frames over the same window (the machine's load
    the same for both): CPU % of one core of each receiving process, frames each of its
    subscriptions took (the fewest), Zenoh subscribers it declared."""
    import zenoh
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(zenoh_config(listen=endpoint))
    publisher = session.declare_publisher(KEY, congestion_control=zenoh.CongestionControl.BLOCK)
    done = CONTEXT.Event()
    ways = {}
    for way in kinds:
        ready, out = CONTEXT.Event(), CONTEXT.Queue()
        process = CONTEXT.Process(target=receiver, args=(endpoint, count, way, ready, done, out),
                                  daemon=True)
        ways[way] = (process, ready, out)
        process.start()
    try:
        for way, (_, ready, _) in ways.items():
            if not ready.wait(60):
                raise RuntimeError(f"the {way} receiving process did not start")
        deadline = time.monotonic() + 20
        while len(session.info.peers_zid()) < len(kinds) or not publisher.matching_status.matching:
            if time.monotonic() > deadline:
                raise RuntimeError("the publisher never matched both receivers")
            time.sleep(0.02)
        time.sleep(0.5)  # (the second receiver's subscription on its way too: Zenoh says matching at the first)
        sent, start = 0, time.monotonic()
        at: dict[str, Any] = {}
        while True:
            now = time.monotonic()
            if not at and now - start >= WARMUP_S:
                at = {"cpu": {way: cpu_ns(p.pid) for way, (p, _, _) in ways.items()},
                      "switches": {way: switches(p.pid) for way, (p, _, _) in ways.items()}, "t": now}
            if at and now - at["t"] >= seconds:
                cpu = {way: 100.0 * (cpu_ns(p.pid) - at["cpu"][way]) / 1e9 / (now - at["t"])
                       for way, (p, _, _) in ways.items()}
                waits = {way: (switches(p.pid) - at["switches"][way]) / (now - at["t"])
                         for way, (p, _, _) in ways.items()}
                break
            publisher.put(frame(sent))
            sent += 1
            time.sleep(max(0.0, start + sent / rate - time.monotonic()))
        time.sleep(0.3)  # (the last frames on their way)
        done.set()
        got = {way: out.get(timeout=20) for way, (_, _, out) in ways.items()}
        return {way: {"cpu_pct": cpu[way], "switches_per_s": waits[way], "sent": sent,
                      "taken_min": min(got[way]["taken"]), "declared": got[way]["declared"]} for way in kinds}
    finally:
        done.set()
        for process, _, _ in ways.values():
            process.join(10)
            if process.is_alive():
                process.kill()
        publisher.undeclare()
        session.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=5.0, help="measuring window of each case")
    parser.add_argument("--counts", type=int, nargs="+", default=list(COUNTS))
    parser.add_argument("--rates", type=int, nargs="+", default=list(RATES))
    parser.add_argument("--ways", nargs=2, default=list(WAYS),
                        choices=("separate", "shared", "direct", "apart", "broader"),
                        help="the baseline and the way measured against it (default: separate shared)")
    parser.add_argument("--name", default="shared_subscriptions", help="results file name")
    args = parser.parse_args()
    ways = tuple(args.ways)
    base, way_ = ways
    load = [os.getloadavg()[0]]
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for index in range(args.rounds):
        for rate in args.rates:
            for count in args.counts:
                case = runs.setdefault(f"{count}x{rate}", {way: [] for way in ways})
                got = measure(count, rate, args.seconds, ways)
                for way in ways:
                    case[way].append(got[way])
                print(f"round {index + 1}, {count} subscription(s), {rate} frames/s: " + "; ".join(
                    f"{way} {got[way]['cpu_pct']:.2f} %, {got[way]['switches_per_s']:.0f} switches/s "
                    f"({got[way]['declared']} Zenoh subscriber(s), each "
                    f"subscription took ≥ {got[way]['taken_min']} of {got[way]['sent']})" for way in ways), flush=True)
        load.append(os.getloadavg()[0])
    machine = f"{os.cpu_count()} cores, load {min(load):.2f}–{max(load):.2f}"
    median = {case: {way: statistics.median(r["cpu_pct"] for r in got[way]) for way in got}
              for case, got in runs.items()}
    waits = {case: {way: statistics.median(r["switches_per_s"] for r in got[way]) for way in got}
             for case, got in runs.items()}
    summary = []
    for case, cpu in median.items():
        count, rate = case.split("x")
        saved = 1.0 - cpu[way_] / cpu[base]
        summary.append({"scenario": f"(issue 35) {count} subscription(s) to one key in one process, {rate} frames/s: "
                                    f"receiving process's CPU, {way_} against {base}",
                        "sonibus": f"{cpu[way_]:.2f} %", "baseline": f"{cpu[base]:.2f} % ({base})",
                        "ratio": f"{cpu[way_] / cpu[base]:.2f}× ({100 * saved:.0f} % saved)",
                        "goal": "≥ 10 % saved" if int(count) > 1 else "", "met": (
                            "yes" if saved >= 0.10 else "no") if int(count) > 1 else ""})
        print(f"{case}: {base} {cpu[base]:.2f} %, {way_} {cpu[way_]:.2f} % ({100 * saved:.0f} % saved); "
              f"switches/s {waits[case][base]:.0f} → {waits[case][way_]:.0f}")
    write(args.name, {"machine": machine, "rounds": args.rounds, "seconds": args.seconds,
                                   "runs": runs, "median": median, "switches_per_s": waits, "summary": summary})
    print(machine)


if __name__ == "__main__":
    main()
