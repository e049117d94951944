"""How long a second terminal waits to be told about this machine's demo (issue 37, item 2).

In a network namespace of its own (its loopback, where the demo listens on 7448, and an
``eth0`` for scouting by multicast, on a LAN of nobody), each trial times a whole
``sonibus send pepper say hello`` process:

- no demo, with ``--demo``: until ``no demo is running on this machine`` (it was 4.7 s:
  2 s waiting for a link, 2 s for the robot's owner, and advice about other machines);
- the demo running, without ``--demo``: until ``a demo runs on this machine: add --demo``
  (it was 4.7 s too, with the same advice); the 2 s of scouting the network stay;
- baseline, same run: the same command with ``--demo`` while the demo runs, answered.

    sudo .venv/bin/python bench/demo_hint.py [--trials 10]

Writes bench/results/demo_hint.json (medians and p99, ratios to the baseline).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from common import latency_stats, write

SONIBUS = str(Path(sys.executable).with_name("sonibus"))
NS = f"sbbench{os.getpid() % 100000}"
NO_DEMO, ADD_DEMO = "no demo is running on this machine", "a demo runs on this machine: add --demo"


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=10)


@contextlib.contextmanager
def namespace() -> Iterator[list[str]]:
    """A namespace with ``lo`` and an ``eth0`` (multicast routed there, nobody on it): the
    prefix that runs a command inside; deleted afterwards."""
    ip("netns", "add", NS)
    try:
        ip("-n", NS, "link", "set", "lo", "up")
        ip("-n", NS, "link", "add", "eth0", "type", "veth", "peer", "name", "peer0")
        ip("-n", NS, "addr", "add", "10.213.250.1/24", "dev", "eth0")
        for link in ("eth0", "peer0"):
            ip("-n", NS, "link", "set", link, "up")
        ip("-n", NS, "route", "add", "224.0.0.0/4", "dev", "eth0")
        yield ["ip", "netns", "exec", NS]
    finally:
        subprocess.run(["ip", "netns", "del", NS], capture_output=True)


def timed(prefix: list[str], *args: str, wanted: str) -> float:
    """Seconds a ``sonibus send pepper say hello ARGS`` took; its output must hold ``wanted``."""
    started = time.perf_counter()
    done = subprocess.run([*prefix, SONIBUS, "send", "pepper", "say", "hello", *args], capture_output=True,
                          text=True, timeout=60)
    took = time.perf_counter() - started
    if wanted not in done.stdout + done.stderr:
        sys.exit(f"send {' '.join(args)}: wanted {wanted!r}, got {done.stdout}{done.stderr}")
    return took


@contextlib.contextmanager
def demo(prefix: list[str]) -> Iterator[None]:
    process = subprocess.Popen([*prefix, SONIBUS, "demo", "--quiet"], stdout=subprocess.PIPE,
                               stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    try:
        for line in process.stdout:
            if line.startswith("sonibus: running"):
                break
        else:
            sys.exit("the demo did not start")
        yield
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(5)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    args = parser.parse_args()
    if os.geteuid() != 0:
        sys.exit("network namespaces need root (the demo's port and scouting stay inside one)")
    times: dict[str, list[float]] = {"no_demo": [], "without_flag": [], "baseline": []}
    with namespace() as prefix:
        for _ in range(args.trials):
            times["no_demo"].append(timed(prefix, "--demo", wanted=NO_DEMO))
        with demo(prefix):
            for _ in range(args.trials):
                times["without_flag"].append(timed(prefix, wanted=ADD_DEMO))
                times["baseline"].append(timed(prefix, "--demo", wanted='"duration"'))
    stats = {name: latency_stats(values) for name, values in times.items()}
    base = stats["baseline"]
    result: dict = {"machine": os.uname().nodename, "trials": args.trials, **stats, "summary": []}
    for name, what in (("no_demo", "--demo, no demo: told to start one"),
                       ("without_flag", "demo running, no --demo: told to add it")):
        s = stats[name]
        ratio = s["p50_us"] / base["p50_us"]
        result["summary"].append({
            "scenario": f"second terminal, {what} (send, whole process), p50 / p99",
            "sonibus": f"{s['p50_us'] / 1e6:.2f} s / {s['p99_us'] / 1e6:.2f} s",
            "baseline": f"{base['p50_us'] / 1e6:.2f} s / {base['p99_us'] / 1e6:.2f} s (send --demo, answered)",
            "ratio": f"{ratio:.1f}×", "goal": "no 5 s wait (was 4.7 s)",
            "met": "yes" if s["p99_us"] < 4.0e6 else "no"})
        print(f"{name:<13} p50 {s['p50_us'] / 1e6:.2f} s  p99 {s['p99_us'] / 1e6:.2f} s  ({ratio:.1f}× baseline)")
    print(f"{'baseline':<13} p50 {base['p50_us'] / 1e6:.2f} s  p99 {base['p99_us'] / 1e6:.2f} s")
    write("demo_hint", result)


if __name__ == "__main__":
    main()
