"""The floor under every sonibus latency: one Zenoh hop between two Python
processes, nothing of sonibus on it. A publisher process puts one frame of 17
joint samples (one key each, as sonibus's per-joint keys) every 10 ms; a subscriber
process stamps each sample in its callback. Latency = arrival − t (one host,
one clock). Variants: the default (`express=False`, batching on), `express=True`,
batching off, a batching time limit of 0, and one key per frame (as
`<robot>/frame`), `express` or not. Baseline, same run: the same 17
datagrams per frame over plain UDP between two processes.

    .venv/bin/python bench/zenoh_hop.py [--frames 600]

Writes bench/results/zenoh_hop.json.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import socket
import time
from typing import Any

from common import free_port, latency_stats, write, zenoh_config

JOINTS = 17
VARIANTS: dict[str, tuple[dict[str, Any], bool, int]] = {  # Zenoh options, express, keys per frame
    "default (express off, batching 1 ms)": ({}, False, JOINTS),
    "express": ({}, True, JOINTS),
    "batching off": ({"transport/link/tx/queue/batching/enabled": False}, False, JOINTS),
    "batching time limit 0": ({"transport/link/tx/queue/batching/time_limit": 0}, False, JOINTS),
    "one key per frame, express": ({}, True, 1),
    "one key per frame, express off (as <robot>/frame)": ({}, False, 1),
}


def _publish(extra: dict[str, Any], express: bool, keys: int, endpoint: str, frames: int, go: Any) -> None:
    import zenoh
    session = zenoh.open(zenoh_config(extra, listen=endpoint))
    publishers = [session.declare_publisher(f"r/joints/J{j}", congestion_control=zenoh.CongestionControl.DROP,
                                            priority=zenoh.Priority.DATA_HIGH, express=express)
                  for j in range(keys)]
    go.wait(10)
    time.sleep(0.5)
    start = time.monotonic()
    for frame in range(frames):
        time.sleep(max(0.0, start + frame * 0.01 - time.monotonic()))
        payload = repr(time.time()).encode()
        for publisher in publishers:
            publisher.put(payload)
    time.sleep(0.3)
    session.close()


def _subscribe(extra: dict[str, Any], endpoint: str, go: Any, done: Any, out: Any) -> None:
    import zenoh
    session = zenoh.open(zenoh_config(extra, connect=endpoint))
    seen: list[float] = []
    subscriber = session.declare_subscriber("r/joints/*",
                                            lambda s: seen.append(time.time() - float(s.payload.to_bytes())))
    go.set()
    done.wait(120)
    subscriber.undeclare()
    session.close()
    out.put(seen)


def zenoh_hop(extra: dict[str, Any], express: bool, keys: int, frames: int) -> dict[str, float]:
    ctx = mp.get_context("spawn")  # never fork a process that has opened a Zenoh session
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    go, done, out = ctx.Event(), ctx.Event(), ctx.Queue()
    publisher = ctx.Process(target=_publish, args=(extra, express, keys, endpoint, frames, go))
    publisher.start()
    subscriber = ctx.Process(target=_subscribe, args=(extra, endpoint, go, done, out))
    subscriber.start()
    publisher.join(frames * 0.01 + 30)
    done.set()
    got = out.get(timeout=30)
    subscriber.join(10)
    return latency_stats(got[keys * 100:])  # the first second: connecting


def _udp_send(port: int, frames: int, go: Any) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    go.wait(10)
    start = time.monotonic()
    for frame in range(frames):
        time.sleep(max(0.0, start + frame * 0.01 - time.monotonic()))
        payload = repr(time.time()).encode()
        for _ in range(JOINTS):
            sock.sendto(payload, ("127.0.0.1", port))


def udp_hop(frames: int) -> dict[str, float]:
    ctx = mp.get_context("spawn")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(1.0)
    go = ctx.Event()
    sender = ctx.Process(target=_udp_send, args=(sock.getsockname()[1], frames, go))
    sender.start()
    go.set()
    seen = []
    try:
        while True:
            seen.append(time.time() - float(sock.recv(64)))
    except TimeoutError:
        pass
    sender.join(10)
    return latency_stats(seen[JOINTS * 100:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    base = udp_hop(args.frames)
    runs = {name: zenoh_hop(*variant, args.frames) for name, variant in VARIANTS.items()}
    print(f"{'path':<40} {'p50_us':>8} {'p99_us':>8} {'p999_us':>8}")
    for name, row in {"plain UDP (baseline)": base, **runs}.items():
        print(f"{name:<40} {row['p50_us']:>8.0f} {row['p99_us']:>8.0f} {row['p999_us']:>8.0f}")
    default = runs[next(iter(VARIANTS))]
    summary = [{"scenario": f"Zenoh hop alone, Python → Python, {name}, p50 / p99",
                "sonibus": f"{row['p50_us']:,.0f} / {row['p99_us']:,.0f} µs",
                "baseline": f"{base['p50_us']:,.0f} / {base['p99_us']:,.0f} µs (plain UDP)",
                "ratio": f"{row['p50_us'] / base['p50_us']:.1f}× / {row['p99_us'] / base['p99_us']:.1f}×"}
               for name, row in runs.items()]
    write("zenoh_hop", {"machine": machine, "joints": JOINTS, "frames": args.frames, "udp": base, "zenoh": runs,
                        "summary": summary, "default_p99_us": default["p99_us"]})
    print(machine)


if __name__ == "__main__":
    main()
