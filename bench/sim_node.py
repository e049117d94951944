"""The sim node beside its floor and beside an older tree's sim, in the same windows
(issue 35: the sim ≤ 1.5× its floor).

One Zenoh session listens; ``show.FRAME_TAKERS`` sessions (one process) take every
``*/frame`` with an empty callback, as the show's nodes take the sim's. Each round, at
the same time: this tree's sim (``sonibus run``, Pepper at 50 Hz, idle motion, its
runner and control session as in the show), with ``--before DIR`` the sim of the tree
in DIR (``DIR/sonibus/{bus,adapters,schemas}``, through ``PYTHONPATH``; the two take
the robot names ``pepper`` and ``pepper2`` in turn), and ``floor.publish`` (a
zenoh-python publisher of the same frames at the same rate). Every frame of each goes
to the same takers. CPU % of one core of each process over ``--seconds``
(``/proc/<pid>/task/*/schedstat``); medians of rounds, and of each round's ratios.

    .venv/bin/python bench/sim_node.py [--rounds 4] [--seconds 8] [--before /tmp/base]

Writes bench/results/sim_node.json and prints a table.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from common import free_port, write, zenoh_config
from floor import CONTEXT, Case, cpu_ns, publish
from show import FRAME_TAKERS, RATE_HZ, WARMUP_S, started, takers_of
from sink_throughput import SONIBUS, stop_process

CONFIG = """[bus]
multicast = false

[nodes.sim]
adapter = "sim"
robot = "{robot}"
model = "pepper"
rate_hz = {rate}
idle = true
"""


def one_round(folder: Path, index: int, seconds: float, before: str) -> dict[str, float]:
    """CPU % of each sim and of the floor over one window, every frame taken by the same sessions."""
    import zenoh
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    anchor = zenoh.open(zenoh_config(listen=endpoint))
    done, fed = CONTEXT.Event(), CONTEXT.Event()
    takers = CONTEXT.Process(target=takers_of, args=(endpoint, FRAME_TAKERS, fed, done), daemon=True)
    trees = {"sim": "", **({"sim_before": before} if before else {})}
    robots = dict(zip(trees, ("pepper", "pepper2") if index % 2 == 0 else ("pepper2", "pepper"), strict=False))
    processes: dict[str, subprocess.Popen[bytes]] = {}
    floor = None
    try:
        takers.start()
        for name, tree in trees.items():
            config = folder / f"{name}.toml"
            config.write_text(CONFIG.format(robot=robots[name], rate=RATE_HZ))
            env = {**os.environ, "PYTHONPATH": tree} if tree else None
            with open(folder / f"{name}.log", "w") as out:
                processes[name] = subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--connect",
                                                    endpoint], stdout=out, stderr=subprocess.STDOUT,
                                                   start_new_session=True, env=env)
        for name, process in processes.items():
            started(folder / f"{name}.log", process)
        floor_fed, out = CONTEXT.Event(), CONTEXT.Queue()
        floor = CONTEXT.Process(target=publish, args=(endpoint, Case(1, 17), seconds + WARMUP_S + 30, floor_fed, out),
                                kwargs={"rate_hz": RATE_HZ}, daemon=True)
        floor.start()
        if not floor_fed.wait(30) or not fed.wait(30):
            raise RuntimeError("the takers did not get frames")
        time.sleep(WARMUP_S)
        pids = {**{name: p.pid for name, p in processes.items()}, "floor": floor.pid}
        before_ns, started_at = {name: cpu_ns(pid) for name, pid in pids.items()}, time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - started_at
        return {name: 100.0 * (cpu_ns(pid) - before_ns[name]) / 1e9 / wall for name, pid in pids.items()}
    finally:
        done.set()
        for process in processes.values():
            stop_process(process)
        if floor is not None:
            floor.kill()  # (it would publish on for its whole time)
            floor.join(10)
        if takers.pid is not None:
            takers.join(10)
            if takers.is_alive():
                takers.kill()
        anchor.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--before", metavar="DIR", default="", help="also the sim of the tree in DIR (DIR/sonibus/...)")
    parser.add_argument("--name", default="sim_node")
    args = parser.parse_args()
    load = [os.getloadavg()[0]]
    rounds = []
    with tempfile.TemporaryDirectory() as name:
        for index in range(args.rounds):
            got = one_round(Path(name), index, args.seconds, args.before)
            got["sim / floor"] = got["sim"] / got["floor"]
            if args.before:
                got["sim_before / floor"] = got["sim_before"] / got["floor"]
                got["sim / sim_before"] = got["sim"] / got["sim_before"]
            rounds.append(got)
            load.append(os.getloadavg()[0])
            print(f"round {index + 1}: " + ", ".join(f"{k} {v:.2f}" for k, v in got.items()), flush=True)
    med = {key: statistics.median(r[key] for r in rounds) for key in rounds[0]}
    machine = f"{os.cpu_count()} cores, load {min(load):.2f}–{max(load):.2f}"
    summary = [{"scenario": f"(sim) Pepper at {RATE_HZ} Hz, idle, its frames taken by {FRAME_TAKERS} sessions: CPU",
                "sonibus": f"{med['sim']:.2f} %", "baseline": f"{med['floor']:.2f} % (a zenoh-python publisher of "
                f"the same frames to the same sessions)", "ratio": f"{med['sim / floor']:.2f}×"}]
    if args.before:
        summary.append({"scenario": "(sim) the same, against the sim of the tree before",
                        "sonibus": f"{med['sim']:.2f} %", "baseline": f"{med['sim_before']:.2f} % ({args.before})",
                        "ratio": f"{med['sim / sim_before']:.2f}×"})
    write(args.name, {"machine": machine, "rate_hz": RATE_HZ, "seconds": args.seconds, "takers": FRAME_TAKERS,
                      "before": args.before, "rounds": rounds, "median": med, "summary": summary})
    print("medians: " + ", ".join(f"{k} {v:.2f}" for k, v in med.items()), machine)


if __name__ == "__main__":
    main()
