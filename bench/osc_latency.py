"""End-to-end OSC latency and loss: robot adapter acquisition → datagram at a
separate receiver process, beside the same OSC sent straight (no bus).

sonibus path: process 1 runs the simulated robots (`sonibus run --only`),
process 2 the OSC sink (extra args t and seq), process 3 receives; with
`--one-process`, robots and sink share process 1, as `sonibus run show.toml`
runs every node of one machine. Baseline:
one process sends the same messages (same rate, same t/seq args) straight to
the receiver. Latency = arrival time − t (one host, one clock).

    .venv/bin/python bench/osc_latency.py [--robots 1,2,10] [--rate 100] [--seconds 10]

Writes bench/results/osc_latency.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import multiprocessing
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import compare, free_port, latency_stats, osc_messages, write

SONIBUS = str(Path(sys.executable).with_name("sonibus"))
JOINTS = 17


def receive(port: int, seconds: float, ready: multiprocessing.Event, out: multiprocessing.Queue) -> None:
    """Record (address, seq, latency) of every message ending in args ,fdi (v, t, seq)."""
    gc.disable()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.5)
    ready.set()
    records = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            data = sock.recv(2048)
        except TimeoutError:
            continue
        now = time.time()
        for message in osc_messages(data):
            address = message[:message.index(b"\0")]
            t, seq = struct.unpack(">di", message[-12:])
            records.append((address, seq, now - t))
    out.put(records)


def summarize(records: list[tuple[bytes, int, float]], robots: int) -> dict[str, float]:
    frames: dict[tuple[bytes, int], int] = {}
    for address, seq, _ in records:
        robot = address.split(b"/")[1]
        frames[(robot, seq)] = frames.get((robot, seq), 0) + 1
    edges = set()  # the first and last frame of each robot are cut by the measuring window
    for robot in {r for r, _ in frames}:
        seqs = [q for r, q in frames if r == robot]
        edges |= {(robot, min(seqs)), (robot, max(seqs))}
    partial_missing = sum(JOINTS - n for key, n in frames.items() if n < JOINTS and key not in edges)
    received = len(records)
    return {"messages": received, "frames": len(frames), **latency_stats([r[2] for r in records]),
            "lost_messages": partial_missing, "loss": partial_missing / max(1, received + partial_missing)}


def baseline(port: int, robots: int, rate: float, seconds: float) -> None:
    """The same OSC (v, t, seq per joint) sent straight, paced like the simulator."""
    from sonibus.adapters.osc.encode import Double, message
    names = [f"J{j}" for j in range(JOINTS)]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    period = 1.0 / rate
    start = time.monotonic()
    frame = 0
    while time.monotonic() - start < seconds:
        for r in range(robots):
            t = time.time()
            for name in names:
                sock.sendto(message(f"/robot{r}/joints/{name}", 0.1, Double(t), frame), ("127.0.0.1", port))
        frame += 1
        time.sleep(max(0.0, start + frame * period - time.monotonic()))


def measure(path: str, robots: int, rate: float, seconds: float, options: str = "",
            sink: str = "", one_process: bool = False) -> dict[str, float]:
    port = free_port(socket.SOCK_DGRAM)
    ready, out = multiprocessing.Event(), multiprocessing.Queue()
    receiver = multiprocessing.Process(target=receive, args=(port, seconds + 2.0, ready, out))
    receiver.start()
    ready.wait(5)
    children = []
    try:
        if path == "baseline":
            baseline(port, robots, rate, seconds)
        else:
            zport = free_port(socket.SOCK_STREAM)
            config = Path(tempfile.mkdtemp()) / "bench.toml"
            nodes = "".join(f'[nodes.robot{r}]\nadapter = "sim"\nrobot = "robot{r}"\nmodel = "pepper"\n'
                            f'rate_hz = {rate}\nidle = true\n\n' for r in range(robots))
            config.write_text(
                f'[bus]\nmulticast = false\n{options}\n\n{nodes}'
                f'[nodes.sound]\nadapter = "osc"\nsubscribe = "*/joints/*"\n'
                f'targets = ["127.0.0.1:{port}"]\nextra = ["t", "seq"]\n{sink}\n')
            robot_nodes = [f"robot{r}" for r in range(robots)]
            if one_process:  # as `sonibus run show.toml` runs every node of one machine
                children.append(subprocess.Popen([SONIBUS, "-v", "run", str(config)], stdout=subprocess.DEVNULL))
            else:
                children.append(subprocess.Popen([SONIBUS, "run", str(config), "--only", *robot_nodes,
                                                  "--listen", f"tcp/127.0.0.1:{zport}"], stdout=subprocess.DEVNULL))
                children.append(subprocess.Popen([SONIBUS, "-v", "run", str(config), "--only", "sound",
                                                  "--connect", f"tcp/127.0.0.1:{zport}"], stdout=subprocess.DEVNULL))
            time.sleep(1.0)  # start-up is not measured
            before = [cpu_seconds(c.pid) for c in children]
            time.sleep(seconds - 1.0)
            cpu = [(cpu_seconds(c.pid) - b) / (seconds - 1.0) * 100 for c, b in zip(children, before, strict=True)]
    finally:
        for child in children:
            child.send_signal(signal.SIGINT)
            child.wait(10)
    records = out.get(timeout=seconds + 30)
    receiver.join(10)
    warmup = 1.0  # the first second: sessions connecting, caches filling
    if path != "baseline" and records:
        records = records[int(len(records) * warmup / seconds):]
    summary = summarize(records, robots)
    if path != "baseline" and one_process:
        summary.update(cpu_process_pct=cpu[0])
    elif path != "baseline":
        summary.update(cpu_robots_pct=cpu[0], cpu_sink_pct=cpu[1], cpu_sink_per_robot_pct=cpu[1] / robots)
    return summary


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_note() -> str:
    return f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="2", help="robot counts, comma-separated (e.g. 1,2,10)")
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--options", default="", help='extra [bus] TOML, e.g. options = {"a/b" = 1}')
    parser.add_argument("--sink", default="", help='extra OSC sink TOML, e.g. "bundle = true"')
    parser.add_argument("--one-process", action="store_true", help="robots and sink in one process")
    parser.add_argument("--name", default="osc_latency", help="results file name")
    args = parser.parse_args()
    runs = []
    for robots in (int(n) for n in args.robots.split(",")):
        before = cpu_note()
        base = measure("baseline", robots, args.rate, args.seconds)
        bus = measure("sonibus", robots, args.rate, args.seconds, args.options, args.sink, args.one_process)
        result = {"robots": robots, "joints": JOINTS, "rate_hz": args.rate, "seconds": args.seconds,
                  "machine": before, "baseline_no_bus": base, "sonibus": bus}
        print(f"-- {robots} robot(s) x {JOINTS} joints x {args.rate:g} Hz ({before})")
        compare(result, base, bus, ["messages", "p50_us", "p99_us", "p999_us", "lost_messages"])
        if args.one_process:
            print(f"CPU: robots and sink {bus['cpu_process_pct']:.1f} %")
        else:
            print(f"CPU: robots {bus['cpu_robots_pct']:.1f} %, sink {bus['cpu_sink_pct']:.1f} % "
                  f"({bus['cpu_sink_per_robot_pct']:.1f} % per robot)")
        runs.append(result)
    write(args.name, {"runs": runs, "sink_options": args.sink, "one_process": args.one_process})


if __name__ == "__main__":
    main()
