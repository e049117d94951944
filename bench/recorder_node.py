"""The recorder node beside its floor and beside an older tree's recorder, in one run
(issue 35: a frame recorded as one MCAP message, where it was a message per joint).

One router; a simulated Pepper at 50 frames/s (idle motion) and the features node (its
derived frames), each a ``sonibus run --only`` process of this tree; two recorder nodes
taking the same bus at the same time, each a process of its own: this tree's and, when
``--before DIR`` is given, the one of the tree in DIR (``DIR/sonibus/{bus,adapters,schemas}``,
imported through ``PYTHONPATH``); both with the Foxglove views (the default). Beside them
``node_floors.recorder_floor`` (a subscriber that decodes each frame and derived frame and
adds it as JSON to an MCAP file on a writer thread), fed by a publisher of its own at the same
rate, a derived frame beside each frame. CPU % of
one core of each process over ``--seconds`` after a warm-up (``/proc/<pid>/stat``), and of
its Python threads (the writer, mostly: Zenoh names its own threads); medians of rounds;
then what each file holds (MCAP messages a frame).

    .venv/bin/python bench/recorder_node.py [--rounds 3] [--seconds 8] [--before /tmp/base]

Writes bench/results/recorder_node.json and prints a table.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import node_floors
from common import free_port, write
from floor import CONTEXT, Case, publish
from show import BUS_OPTIONS, SHOW, WARMUP_S, started, window
from sink_throughput import SONIBUS, stop_process, thread_cpu

RATE_HZ = 50
# show.py's installation (its sim, features and recorder are run here; the recorder writes show-*.mcap),
# and the recorder of the older tree beside it
BEFORE = """
[nodes.recorder_before]
adapter = "recorder"
path = "{folder}/before-{{time}}.mcap"
status_every_s = 0
"""


def run(config: Path, log: Path, node: str, endpoint: str, pythonpath: str | None = None) -> subprocess.Popen[bytes]:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    with open(log, "w") as out:
        return subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--only", node, "--connect", endpoint],
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True, env=env)


def python_threads(pid: int) -> float:
    """CPU seconds of ``pid``'s threads that kept the process's name (Python's; Zenoh names its own)."""
    threads = thread_cpu(pid)
    own = Path(f"/proc/{pid}/comm").read_text().strip()
    return sum(v for k, v in threads.items() if k == own)


def held(folder: Path, prefix: str) -> dict[str, Any]:
    """MCAP messages in the files of ``prefix`` and how many of them are frames (``<robot>/frame``)."""
    from mcap.reader import make_reader
    messages, frames, joints = 0, 0, 0
    for path in glob.glob(str(folder / f"{prefix}-*.mcap")):
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is None or summary.statistics is None:
            continue
        counts = summary.statistics.channel_message_counts
        for cid, channel in summary.channels.items():
            n = counts.get(cid, 0)
            messages += n
            frames += n if channel.topic == "pepper/frame" else 0
            joints += n if channel.topic.startswith("pepper/joints/") else 0
    return {"messages": messages, "frames": frames, "joint_messages": joints,
            "messages_per_frame": round(messages / frames, 2) if frames else None}


def measure(seconds: float, before: str | None) -> dict[str, Any]:
    folder = Path(tempfile.mkdtemp(prefix="recorder-node-"))
    config = folder / "show.toml"
    ports = {name: free_port() for name in ("osc", "gateway", "web", "oscquery", "foxglove")}  # (not run here)
    config.write_text(SHOW.format(rate=RATE_HZ, folder=folder, bus_options=BUS_OPTIONS, **ports)
                      + BEFORE.format(folder=folder))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    processes: dict[str, subprocess.Popen[bytes]] = {}
    done, ready = CONTEXT.Event(), CONTEXT.Event()
    floor_endpoint = f"tcp/127.0.0.1:{free_port()}"
    floor = CONTEXT.Process(target=node_floors.recorder_floor, args=(floor_endpoint, str(folder), ready, done),
                            daemon=True)
    feeder = None
    try:
        with open(folder / "router.log", "w") as out:
            processes["router"] = subprocess.Popen([SONIBUS, "router", "--no-multicast", "--listen", endpoint],
                                                   stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        started(folder / "router.log", processes["router"], "sonibus router")
        nodes = {"recorder": None, "sim": None, "features": None}
        if before:
            nodes["recorder_before"] = before
        for node, path in nodes.items():
            processes[node] = run(config, folder / f"{node}.log", node, endpoint, path)
        for node in nodes:
            started(folder / f"{node}.log", processes[node])
        floor.start()
        if not ready.wait(30):
            raise RuntimeError("the recorder floor did not start")
        fed, out_queue = CONTEXT.Event(), CONTEXT.Queue()
        feeder = CONTEXT.Process(target=publish, args=(floor_endpoint, Case(1, 17), seconds + WARMUP_S + 2, fed,
                                                       out_queue), kwargs={"rate_hz": RATE_HZ, "derived": True},
                                 daemon=True)
        feeder.start()
        if not fed.wait(30):
            raise RuntimeError("the floor's publisher did not find it")
        time.sleep(WARMUP_S)
        recorders = [n for n in ("recorder", "recorder_before") if n in processes]
        threads = {n: python_threads(processes[n].pid) for n in recorders}
        started_at = time.monotonic()
        cpu = window({**{n: processes[n].pid for n in recorders}, "floor": floor.pid}, seconds)
        wall = time.monotonic() - started_at
        for n in recorders:
            cpu[f"{n} python threads"] = 100.0 * (python_threads(processes[n].pid) - threads[n]) / wall
        return {"cpu": cpu, "folder": folder}
    finally:
        done.set()
        for process in (feeder, floor):
            if process is not None:
                process.join(10)
                if process.is_alive():
                    process.kill()
        for process in processes.values():
            stop_process(process)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--before", help="a folder holding sonibus/{bus,adapters,schemas} of an older tree")
    parser.add_argument("--name", default="recorder_node")
    args = parser.parse_args()
    rounds, files = [], {}
    for n in range(args.rounds):
        found = measure(args.seconds, args.before)
        rounds.append(found["cpu"])
        files = {prefix: held(found["folder"], prefix) for prefix in ("show", "before") if
                 glob.glob(str(found["folder"] / f"{prefix}-*.mcap"))}
        print(f"round {n + 1}: " + ", ".join(f"{k} {v:.2f}" for k, v in found["cpu"].items()), flush=True)
    median = {k: round(statistics.median(r[k] for r in rounds), 2) for k in rounds[0]}
    ratios = {f"{k} / floor": round(median[k] / median["floor"], 2) for k in ("recorder", "recorder_before")
              if k in median}
    if "recorder_before" in median:
        ratios["recorder / recorder_before"] = round(median["recorder"] / median["recorder_before"], 2)
        ratios["python threads: recorder / recorder_before"] = round(
            median["recorder python threads"] / median["recorder_before python threads"], 2)
    load = os.getloadavg()
    print(f"\nrecorder node, one robot at {RATE_HZ} Hz with features, medians of {args.rounds} rounds of "
          f"{args.seconds:g} s (CPU % of a core; load {load[0]:.1f}):")
    for k, v in median.items():
        print(f"  {k:38s} {v:6.2f}")
    for k, v in ratios.items():
        print(f"  {k:38s} {v:6.2f}x")
    for prefix, figures in files.items():
        print(f"  {prefix} file: {figures}")
    write(args.name, {"scenario": f"recorder node vs its floor and {args.before or 'nothing'}: 1 robot x 17 joints "
                                  f"at {RATE_HZ} Hz, features, Foxglove views on",
                      "rounds": rounds, "median": median, "ratios": ratios, "files": files,
                      "load": [round(x, 2) for x in load]})


if __name__ == "__main__":
    main()
