"""What a sonibus process pays with nothing to do (issue 35): each node alone in its own
``sonibus run``, no robot on the bus and no client, against the same node of another tree.

    git archive 4d2367f bus adapters schemas | tar -x -C /tmp/base/sonibus
    .venv/bin/python bench/idle.py --against /tmp/base --seconds 60 --name idle

Every process connects to one ``sonibus router`` (loopback, no multicast); this tree's nodes
and those of the tree in ``--against`` run side by side on the same bus, so both pay the same
links. Per node, over the same window: CPU % of one core (``/proc/<pid>/task/*/schedstat``)
and voluntary context switches a second (each a thread that slept and was woken: the count
the machine's load does not blur). Writes bench/results/<name>.json and prints a table.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from common import free_port, write
from floor import switches
from show import BUS_OPTIONS, RATE_HZ, SHOW, sonibus, started, window
from sink_throughput import SONIBUS, stop_process

NODES = ("web", "osc", "oscquery", "recorder", "features", "gateway", "foxglove")  # (show.py's; not midi: JACK)
def config(folder: Path, name: str) -> Path:
    """show.py's show, ports of its own (each node is run alone: ``--only``; no sim is)."""
    ports = {name: free_port(socket.SOCK_DGRAM if name in ("osc", "gateway") else socket.SOCK_STREAM)
             for name in ("osc", "gateway", "web", "oscquery", "foxglove")}
    path = folder / f"{name}.toml"
    path.write_text(SHOW.format(rate=RATE_HZ, folder=folder, bus_options=BUS_OPTIONS, **ports))
    return path


def measure(folder: Path, nodes: tuple[str, ...], against: str, seconds: float) -> tuple[dict[str, float],
                                                                                          dict[str, float]]:
    """CPU % and voluntary switches a second of each node's process (``"<node> @against"``: the other tree's)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    processes: dict[str, subprocess.Popen[bytes]] = {}
    ours, theirs = config(folder, "ours"), config(folder, "theirs")
    try:
        with open(folder / "router.log", "w") as out:
            processes["router"] = subprocess.Popen([SONIBUS, "router", "--no-multicast", "--listen", endpoint],
                                                   stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        started(folder / "router.log", processes["router"], "sonibus router")
        for node in nodes:
            processes[node] = _run(ours, folder / f"{node}.log", node, endpoint, "")
            if against:
                processes[f"{node} @against"] = _run(theirs, folder / f"{node}-against.log", node, endpoint, against)
        for name, process in processes.items():
            if name != "router":
                started(folder / f"{name.replace(' @against', '-against')}.log", process)
        time.sleep(5.0)  # (every link made, every first query answered)
        before = {name: switches(p.pid) for name, p in processes.items()}
        cpu = window({name: p.pid for name, p in processes.items()}, seconds)
        waits = {name: (switches(p.pid) - before[name]) / seconds for name, p in processes.items()}
        return cpu, waits
    finally:
        for process in processes.values():
            stop_process(process)


def _run(path: Path, log: Path, node: str, endpoint: str, tree: str) -> subprocess.Popen[bytes]:
    return sonibus(path, log, "--only", node, "--connect", endpoint, tree=tree)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--against", metavar="DIR", default="", help="a folder holding another tree's sonibus/")
    parser.add_argument("--nodes", default=",".join(NODES))
    parser.add_argument("--name", default="idle")
    args = parser.parse_args()
    nodes = tuple(args.nodes.split(","))
    rounds: list[tuple[dict[str, float], dict[str, float]]] = []
    for _ in range(args.rounds):
        with tempfile.TemporaryDirectory() as folder:
            rounds.append(measure(Path(folder), nodes, args.against, args.seconds))
    cpu = {name: statistics.median(r[0][name] for r in rounds) for name in rounds[0][0]}
    waits = {name: statistics.median(r[1][name] for r in rounds) for name in rounds[0][1]}
    summary = []
    print(f"{'node':<10} {'CPU %':>7} {'switches/s':>11}" + (f" {'against CPU %':>14} {'switches/s':>11} {'ratio':>6}"
                                                            if args.against else ""))
    for node in (*nodes, "router"):
        row = f"{node:<10} {cpu[node]:7.2f} {waits[node]:11.0f}"
        what = "their router" if node == "router" else f"{node} node alone, no robot, no client"
        entry = {"scenario": f"(idle) {what}: CPU, wake-ups",
                 "sonibus": f"{cpu[node]:.2f} % of a core, {waits[node]:.0f} switches/s", "cpu": round(cpu[node], 3),
                 "switches_per_s": round(waits[node], 1)}
        other = f"{node} @against"
        if other in cpu:
            ratio = cpu[node] / cpu[other] if cpu[other] else float("nan")
            row += f" {cpu[other]:14.2f} {waits[other]:11.0f} {ratio:6.2f}"
            entry.update({"baseline": f"{cpu[other]:.2f} %, {waits[other]:.0f} switches/s ({args.against})",
                          "ratio": f"{ratio:.2f}×", "baseline_cpu": round(cpu[other], 3),
                          "baseline_switches_per_s": round(waits[other], 1)})
        print(row)
        summary.append(entry)
    load = Path("/proc/loadavg").read_text().split()[:3]
    write(args.name, {"seconds": args.seconds, "rounds": args.rounds, "load": load, "cpu": cpu,
                      "switches_per_s": waits, "summary": summary})


if __name__ == "__main__":
    main()
