"""The CPU floor under the OSC sink's "≤ 2 % of a core per robot": what it costs
a process just to receive one message per frame (100 per robot per second)
from Zenoh, with nothing done with it. A publisher process puts 400-byte
messages (about a Pepper frame) on one key at 100 or 200 messages/s; the
subscriber process (zenoh-python, an empty callback) is measured from
/proc. Baseline, same run: a plain Python UDP receiver (blocking ``recv``)
given the same datagrams at the same rates.

    .venv/bin/python bench/receive_cpu.py [--seconds 8]

Writes bench/results/receive_cpu.json.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing as mp
import os
import socket
import time
from typing import Any

from common import free_port, write, zenoh_config
from sink_throughput import cpu_seconds

CONTEXT = mp.get_context("spawn")  # never fork a process that has opened a Zenoh session
PAYLOAD = b"x" * 400


def _zenoh_subscriber(endpoint: str, done: Any) -> None:
    import zenoh
    session = zenoh.open(zenoh_config(connect=endpoint))
    subscriber = session.declare_subscriber("r/frame", lambda sample: None)
    done.wait(120)
    subscriber.undeclare()
    session.close()


def _udp_receiver(port: int, done: Any) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.5)
    while not done.is_set():
        with contextlib.suppress(TimeoutError):
            sock.recv(2048)


def _paced(send: Any, rate: float, seconds: float) -> None:
    start = time.monotonic()
    for n in range(round(rate * seconds)):
        send()
        time.sleep(max(0.0, start + (n + 1) / rate - time.monotonic()))


def measure(path: str, rate: float, seconds: float) -> float:
    """CPU % of one core used by the receiving process while ``rate`` messages/s arrive."""
    done = CONTEXT.Event()
    if path == "zenoh":
        import zenoh
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        session = zenoh.open(zenoh_config(listen=endpoint))
        publisher = session.declare_publisher("r/frame", express=True)
        receiver = CONTEXT.Process(target=_zenoh_subscriber, args=(endpoint, done))
        receiver.start()
        deadline = time.monotonic() + 20
        while not publisher.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.05)
        send, close = (lambda: publisher.put(PAYLOAD)), session.close
    else:
        port = free_port(socket.SOCK_DGRAM)
        receiver = CONTEXT.Process(target=_udp_receiver, args=(port, done))
        receiver.start()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        send, close = (lambda: sock.sendto(PAYLOAD, ("127.0.0.1", port))), sock.close
    try:
        time.sleep(1.0)  # start-up is not measured
        before, started = cpu_seconds(receiver.pid), time.monotonic()
        _paced(send, rate, seconds)
        return 100.0 * (cpu_seconds(receiver.pid) - before) / (time.monotonic() - started)
    finally:
        done.set()
        receiver.join(10)
        close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    runs = {}
    for rate in (100.0, 200.0):
        runs[f"{rate:g}"] = {"udp_pct": measure("udp", rate, args.seconds),
                             "zenoh_pct": measure("zenoh", rate, args.seconds)}
        print(f"{rate:g} messages/s: plain UDP receiver {runs[f'{rate:g}']['udp_pct']:.2f} %, "
              f"zenoh-python subscriber {runs[f'{rate:g}']['zenoh_pct']:.2f} % of a core", flush=True)
    per_robot = runs["100"]
    summary = [{"scenario": "receiving 100 messages/s (one robot's frames), nothing done with them: CPU",
                "sonibus": f"{per_robot['zenoh_pct']:.2f} % (zenoh-python subscriber)",
                "baseline": f"{per_robot['udp_pct']:.2f} % (plain UDP receiver)",
                "ratio": f"{per_robot['zenoh_pct'] / max(0.01, per_robot['udp_pct']):.0f}×",
                "goal": "(floor under the sink's ≤ 2 %)", "met": ""}]
    write("receive_cpu", {"machine": machine, "seconds": args.seconds, "runs": runs, "summary": summary})
    print(machine)


if __name__ == "__main__":
    main()
