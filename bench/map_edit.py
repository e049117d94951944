"""Editing a map while it runs: 50 maps on a Pepper's frames at 100 Hz (bench/map_cpu.py's),
and edits of one of them (its breakpoints moved) as the operator page sends them.

- edit round trip: a ``<node>/maps/edit`` request to its reply, the edit applied (p50, p99),
  beside a query of the same node's ``<node>/info/derived`` (a reply of cached bytes), same run;
- edit to output: the reply to the first output through the new curve;
- the worker's CPU while edits come 20 times a second, beside none (same run).

    .venv/bin/python bench/map_edit.py [--edits 200] [--seconds 4]

Writes bench/results/map_edit.json and prints it.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from typing import Any

from common import latency_stats, write
from map_cpu import MAPS, running, stage, thread_cpu

from sonibus.adapters.map import MapNode
from sonibus.bus import Bus, codec, keys


def points(i: int) -> list[list[float]]:
    return [[0, 0], [0.5, 0.2 + 0.6 * (i % 2)], [1, 1]]


def round_trips(bus: Bus, edits: int) -> dict[str, Any]:
    edit, described, to_output = [], [], []
    outputs: list[tuple[float, float]] = []  # (arrival, value) of m1's outputs
    lock = threading.Lock()

    def take(sample: Any) -> None:
        with lock:
            outputs.append((time.perf_counter(), codec.decode(sample.payload.to_bytes())["v"]))
    subscriber = bus.session.declare_subscriber("sound/derived/map/m1", take)
    try:
        for i in range(edits):
            began = time.perf_counter()
            answer = bus.query(keys.maps("sound", "edit"), {"map": "m1", "set": {"points": points(i)}}, timeout=5)
            replied = time.perf_counter()
            if not (answer and answer[0].get("ok")):
                raise SystemExit(f"edit refused: {answer}")
            edit.append(replied - began)
            began = time.perf_counter()
            bus.query(keys.derived_info("sound"), timeout=5)
            described.append(time.perf_counter() - began)
            deadline = time.monotonic() + 2
            while time.monotonic() < deadline:  # the first output after the reply: the new curve's?
                with lock:
                    later = [o for o in outputs if o[0] > replied]
                if later:
                    to_output.append(later[0][0] - replied)
                    break
                time.sleep(0.0005)
    finally:
        subscriber.undeclare()
    edited, queried = latency_stats(edit), latency_stats(described)
    return {"edit": edited, "info_query": queried, "reply_to_next_output": latency_stats(to_output),
            "edit_over_query_p50": round(edited["p50_us"] / queried["p50_us"], 2)}


def cpu_with_edits(bus: Bus, node: MapNode, seconds: float) -> dict[str, Any]:
    quiet = thread_cpu("sound:map", seconds, lambda: node.stats["sent"])
    stop = threading.Event()

    def edit() -> None:
        i = 0
        while not stop.wait(0.05):
            bus.query(keys.maps("sound", "edit"), {"map": "m1", "set": {"points": points(i)}}, timeout=5)
            i += 1
    editor = threading.Thread(target=edit, daemon=True)
    editor.start()
    try:
        busy = thread_cpu("sound:map", seconds, lambda: node.stats["sent"])
    finally:
        stop.set()
        editor.join()
    return {"no_edits": quiet, "edits_20_per_s": busy,
            "ratio": round(busy["cpu_percent"] / max(quiet["cpu_percent"], 1e-9), 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--edits", type=int, default=200)
    parser.add_argument("--seconds", type=float, default=4.0)
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    with stage() as (robot_session, node_session), running(Bus(node_session)) as node:
        asker = Bus(robot_session, node="asker")  # (the page's side: across the link, as a web node asks)
        result = {"maps": MAPS, "rate_hz": 100, **round_trips(asker, args.edits),
                  "cpu": cpu_with_edits(asker, node, args.seconds)}
    edit, query, cpu = result["edit"], result["info_query"], result["cpu"]
    result["machine"] = machine
    result["summary"] = [
        {"scenario": "(34) a map edited while 50 maps run at 100 Hz: edit round trip p50 / p99",
         "sonibus": f"{edit['p50_us'] / 1000:.2f} / {edit['p99_us'] / 1000:.2f} ms",
         "baseline": f"{query['p50_us'] / 1000:.2f} / {query['p99_us'] / 1000:.2f} ms (info query, same node)",
         "ratio": f"{result['edit_over_query_p50']:.1f}×", "goal": "", "met": ""},
        {"scenario": "(34) edit reply → the map's next output at a subscriber (frames every 10 ms), p50 / p99",
         "sonibus": f"{result['reply_to_next_output']['p50_us'] / 1000:.1f} / "
                    f"{result['reply_to_next_output']['p99_us'] / 1000:.1f} ms",
         "baseline": "10 ms (one frame's period)", "ratio": "", "goal": "", "met": ""},
        {"scenario": "(34) the map worker's CPU with 20 edits/s",
         "sonibus": f"{cpu['edits_20_per_s']['cpu_percent']} %",
         "baseline": f"{cpu['no_edits']['cpu_percent']} % (no edits)", "ratio": f"{cpu['ratio']:.2f}×",
         "goal": "", "met": ""}]
    write("map_edit", result)
    for row in result["summary"]:
        print(f"{row['scenario']}: {row['sonibus']} (baseline {row['baseline']})")


if __name__ == "__main__":
    main()
