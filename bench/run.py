"""`make bench`: every benchmark in turn, then the summary table in
docs/performance.md (between its `bench:begin` and `bench:end` marks), each
sonibus figure beside its baseline from the same run and the goal.

    .venv/bin/python bench/run.py [--only floor sink_throughput ...] [--table-only]
    .venv/bin/python bench/run.py --only soak_show_long     # the show soak's long form: 70 minutes

Each script writes bench/results/<name>.json; this file only runs them and
reads what they wrote, so a script can also be run alone.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
DOC = HERE.parent / "docs" / "performance.md"
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"

# results name → (script, arguments, time limit in s); together about half an hour
SCRIPTS: dict[str, tuple[str, list[str], float]] = {
    # the OSC sink beside the floor of the stack (issue 27): 1, 2, 10 robots; 64 and 128 joints; bundles;
    # the floor as issue 27 defined it (sendto) and on a connected socket, as the sink sends
    "floor": ("floor", ["--rounds", "3", "--seconds", "4", "--connected-floor"], 1200),
    "osc_latency_one_process": ("osc_latency", ["--robots", "2", "--seconds", "8", "--one-process",
                                                "--name", "osc_latency_one_process"], 60),
    "show": ("show", ["--rounds", "2", "--seconds", "8"], 300),  # a full show, node by node (issue 27)
    "idle": ("idle", ["--seconds", "20"], 120),  # each node of the show alone, idle: CPU and wake-ups (issue 35)
    # N subscriptions to one key in one process: a Zenoh subscriber each, or one shared (issue 35)
    "shared_subscriptions": ("shared_subscriptions", ["--rounds", "3", "--seconds", "5"], 400),
    # a robot's subscriptions (pepper/frame) beside every robot's (*/frame): two Zenoh subscribers, or one
    "shared_subscriptions_broader": ("shared_subscriptions", ["--rounds", "3", "--seconds", "5", "--ways", "apart",
                                                              "broader", "--counts", "2", "8", "--rates", "50",
                                                              "--name", "shared_subscriptions_broader"], 200),
    "floor_instructions": ("floor_instructions", [], 900),  # the OSC sink's frame path in instructions (callgrind)
    # the MIDI sink's and the web node's frame paths beside their floors', in instructions (callgrind; issue 35)
    "node_instructions": ("node_instructions", [], 300),
    # the show's seven takers of a frame in one process: instructions a tick (callgrind; issue 35)
    "verdicts": ("verdicts", [], 300),
    "sink_throughput": ("sink_throughput", [], 120),
    "sink_throughput_bundles": ("sink_throughput", ["--bundles", "--name", "sink_throughput_bundles",
                                                    "--rates", "40000", "100000", "150000", "200000"], 90),
    "naoqi_rate": ("naoqi_rate", [], 90),
    "midi_rate": ("midi_rate", [], 90),
    "midi_in_latency": ("midi_in_latency", [], 60),  # midi-in's JACK input: JACK-Client beside rtmidi (issue 33)
    # rtmidi's JACK output opened and closed beside a Python JACK client in one process: its stall
    "jack_rtmidi_stall": ("jack_rtmidi_stall", [], 60),
    "recorder_rate": ("recorder_rate", [], 90),
    # the recorder node beside its floor, one robot at 50 Hz with features (issue 35)
    "recorder_node": ("recorder_node", ["--rounds", "2", "--seconds", "8"], 180),
    "sim_node": ("sim_node", ["--rounds", "4", "--seconds", "8"], 240),  # the sim beside its floor (issue 35)
    "sim_instructions": ("sim_instructions", [], 300),  # the sim's frame beside the floor's in instructions (callgrind)
    # Foxglove's and the recorder's own Python per bus message, a fixed workload replayed (issue 35)
    "foxglove_replay": ("foxglove_replay", ["--rounds", "3"], 300),
    "stop_latency": ("stop_latency", [], 90),
    "stop_flood": ("stop_flood", [], 400),  # stop on each path alone and right after floods (issue 33)
    "stop_flood_heavy": ("stop_flood", ["--flood", "5000", "--rate", "50000", "--name", "stop_flood_heavy"], 400),
    "demo_hint": ("demo_hint", [], 120),  # a second terminal told about this machine's demo (issue 37)
    "features": ("features", [], 240),  # with its instruction counts under callgrind (issue 35)
    "map_cpu": ("map_cpu", [], 60),  # the map node's 50 maps at 100 Hz beside a hand-written loop (issue 34)
    "clap_nod": ("clap_nod", [], 120),  # a clap into JACK → the robot nods: sound to movement (issue 34)
    "map_edit": ("map_edit", [], 90),  # a map edited while it runs: round trip, CPU with 20 edits/s (issue 34)
    "zenoh_hop": ("zenoh_hop", [], 90),
    "receive_cpu": ("receive_cpu", [], 60),
    "gate": ("gate", [], 60),
    "web": ("web", ["--trials", "300"], 90),  # a web page's command round trip (issue 17)
    "web_page": ("web_page", [], 120),  # the operator page in headless Chromium: updates/s, click → robot → page
    "pacing": ("pacing", [], 90),  # the sim's pacing, the OSC rate cap, replay timing: no longer asserted by tests
    "audio": ("audio", ["--seconds", "20"], 330),  # JACK ↔ robot audio over the bus and over plain UDP
    "soak": ("soak", ["--minutes", "3"], 330),  # the fuzz suite of tests/fuzz for minutes
    # crafted recordings (issue 33): the suite's fuzz of files at length; what checking every message costs a reading
    "recording_fuzz": ("recording_fuzz", ["--files", "1500"], 300),
    "ros2_cdr": ("ros2_cdr", ["--instructions", "17"], 300),  # ROS 2 CDR, ours beside rosbags (and msgpack)
    "ros2_rate": ("ros2_rate", [], 300),  # ROS 2 JointState publish → OSC, beside NAOqi → OSC
    "urdf_parse": ("urdf_parse", [], 300),  # reading a URDF beside the XML parser alone: linear, loops refused
    "soak_show": ("soak_show", ["--minutes", "6"], 600),  # a whole show, clients coming and going: memory flat?
    # the long form of the show soak (issue 25: an hour or more, the RSS slope judged); only when asked for
    "soak_show_long": ("soak_show", ["--minutes", "70", "--name", "soak_show_long"], 80 * 60),
}
ON_REQUEST = {"soak_show_long"}  # not in a plain `make bench`: `bench/run.py --only soak_show_long`


def run(names: list[str]) -> dict[str, str]:
    """Run the scripts; what happened to each ("ok", or why not)."""
    outcome = {}
    for name in names:
        script, args, limit = SCRIPTS[name]
        started = time.monotonic()
        print(f"== {name}: {script}.py {' '.join(args)}", flush=True)
        try:
            done = subprocess.run([sys.executable, str(HERE / f"{script}.py"), *args], cwd=HERE, timeout=limit)
            outcome[name] = "ok" if done.returncode == 0 else f"exit {done.returncode}"
        except subprocess.TimeoutExpired:
            outcome[name] = f"over its {limit:g} s limit"
        print(f"== {name}: {outcome[name]} in {time.monotonic() - started:.0f} s", flush=True)
    return outcome


def result(name: str) -> dict[str, Any] | None:
    path = HERE / "results" / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def _us(value: float) -> str:
    return f"{value:,.0f} µs" if value < 10_000 else f"{value / 1000:,.1f} ms"


Row = tuple[str, str, str, str, str, str]  # scenario, sonibus, baseline, ratio, goal, met


def rows_osc_latency(r: dict[str, Any]) -> list[Row]:
    out = []
    shape = f" ({r['sink_options']})" if r.get("sink_options") else ""
    shape += " (robots and sink in one process)" if r.get("one_process") else ""
    for run_ in r.get("runs", []):
        bus, base, n = run_["sonibus"], run_["baseline_no_bus"], run_["robots"]
        two = n == 2
        met = bus["p50_us"] <= 2 * base["p50_us"] and bus["p99_us"] <= 500 and bus["lost_messages"] == 0
        out.append((f"(a) {n} robot(s) × 17 × 100 Hz → OSC{shape}, p50 / p99",
                    f"{_us(bus['p50_us'])} / {_us(bus['p99_us'])}, lost {bus['lost_messages']}",
                    f"{_us(base['p50_us'])} / {_us(base['p99_us'])} (no bus)",
                    f"{bus['p50_us'] / base['p50_us']:.1f}× / {bus['p99_us'] / base['p99_us']:.1f}×",
                    "p50 ≤ 2×, p99 ≤ 0.5 ms, no loss" if two else "no loss",
                    ("yes" if met else "no") if two else ("yes" if bus["lost_messages"] == 0 else "no")))
        if "cpu_sink_per_robot_pct" in bus:
            out.append((f"(a) OSC sink CPU per robot ({n} robot(s)){shape}", f"{bus['cpu_sink_per_robot_pct']:.1f} %",
                        "", "", "≤ 2 % of a core", "yes" if bus["cpu_sink_per_robot_pct"] <= 2 else "no"))
    return out


def rows_naoqi_rate(r: dict[str, Any]) -> list[Row]:
    out = []
    for delay, runs in r.get("runs", {}).items():
        bus, old = runs["sonibus_max"], runs["pepperosc_max"]
        ratio = bus["rate_hz"] / old["rate_hz"]
        out.append((f"(c) NAOqi frames/s, {delay.replace('_', ' ')}", f"{bus['rate_hz']:,.0f}/s",
                    f"{old['rate_hz']:,.1f}/s (PepperOSC)", f"{ratio:.1f}×", "≥ 10×", "yes" if ratio >= 10 else "no"))
        paced = runs["sonibus_100hz"]
        out.append((f"(c) NAOqi jitter at 100 Hz, {delay.replace('_', ' ')}", f"p99 {paced['jitter_p99_ms']:.2f} ms",
                    f"p99 {runs['pepperosc_100hz']['jitter_p99_ms']:.2f} ms (PepperOSC)", "", "p99 ≤ 1 ms",
                    "yes" if paced["jitter_p99_ms"] <= 1 else "no"))
    return out


def rows_features(r: dict[str, Any]) -> list[Row]:
    f, base = r["features"], r["decode_only"]
    before = [("features per Pepper frame against before issue 35's per-frame work, p50 / p99",
               f"{_us(f['p50_us'])} / {_us(f['p99_us'])}",
               f"{_us(r['before']['p50_us'])} / {_us(r['before']['p99_us'])} (before)",
               f"{r['after_to_before_p50']:.2f}× / {r['after_to_before_p99']:.2f}×", "", "")] if "before" in r else []
    counted = r.get("instructions_per_frame") or {}
    if counted:
        before.append(("features per Pepper frame, instructions (callgrind)",
                       f"{counted['features'] / 1000:,.0f}k ({counted['features'] / counted['decode_only']:.1f}× "
                       "decode only)", f"{counted['before'] / 1000:,.0f}k (before), decode only "
                       f"{counted['decode_only'] / 1000:,.0f}k", f"{counted['features'] / counted['before']:.2f}×",
                       "", ""))
    if "on_bus_before" in r:
        before.append(("features node on the bus, CPU taking frames, against before issue 35's per-frame work",
                       f"{r['on_bus']['cpu_percent']:.1f} % of a core",
                       f"{r['on_bus_before']['cpu_percent']:.1f} % (before)", f"{r['on_bus_after_to_before']:.2f}×",
                       "", ""))
    return [("features per Pepper frame, p50 / p99", f"{_us(f['p50_us'])} / {_us(f['p99_us'])}",
             f"{_us(base['p50_us'])} / {_us(base['p99_us'])} (decode only)", f"{f['p50_us'] / base['p50_us']:.1f}×",
             "", "")] + before + ([("features + expressive per Pepper frame, p50 / p99",
                           f"{_us(r['expressive']['p50_us'])} / {_us(r['expressive']['p99_us'])}",
                           f"{_us(f['p50_us'])} / {_us(f['p99_us'])} (features without)",
                           f"{r['expressive']['p50_us'] / f['p50_us']:.1f}× / "
                           f"{r['expressive']['p99_us'] / f['p99_us']:.1f}×", "", "")] if "expressive" in r else []) + (
        [("features node on the bus, CPU taking frames: default / + expressive",
          f"{r['on_bus']['cpu_percent']:.1f} % / {r['on_bus_expressive']['cpu_percent']:.1f} % of a core",
          "default features", f"{r['on_bus_expressive_ratio']:.1f}×", "", "")] if "on_bus_expressive" in r else [])


def rows_generic(r: dict[str, Any]) -> list[Row]:
    """Scripts that state their own summary rows: ``{"summary": [{scenario, sonibus, baseline, ...}]}``."""
    return [(s["scenario"], s["sonibus"], s.get("baseline", ""), s.get("ratio", ""), s.get("goal", ""),
             s.get("met", "")) for s in r.get("summary", [])]


ROWS: dict[str, Callable[[dict[str, Any]], list[Row]]] = {
    "osc_latency_one_process": rows_osc_latency, "naoqi_rate": rows_naoqi_rate,
    "features": rows_features,
}


def table() -> str:
    lines = ["| scenario | sonibus | baseline, same run | ratio | goal | met |", "|---|---|---|---|---|---|"]
    machines = set()
    for name in SCRIPTS:
        r = result(name)
        if r is None:
            lines.append(f"| {name} | not run{' (only with --only ' + name + ')' if name in ON_REQUEST else ''} "
                         "| | | | |")
            continue
        machines.add(str(r.get("machine") or (r.get("runs") or [{}])[0].get("machine", "")))
        for row in ROWS.get(name, rows_generic)(r):
            lines.append("| " + " | ".join(row) + " |")
    when = time.strftime("%Y-%m-%d %H:%M", time.localtime())
    # (each row is its script's last results, whenever it ran: ``--only`` and a script run alone rewrite theirs)
    return "\n".join([f"Table written {when} from each script's last results in `bench/results/` (a script run "
                      f"alone, or `--only`, rewrites its own rows; `make bench` all of them); "
                      f"{'; '.join(sorted(m for m in machines if m))}.", "", *lines])


def update_doc() -> None:
    text = DOC.read_text(encoding="utf-8")
    block = f"{BEGIN}\n{table()}\n{END}"
    if BEGIN in text and END in text:
        text = text[:text.index(BEGIN)] + block + text[text.index(END) + len(END):]
    else:
        head, sep, rest = text.partition("\n## ")
        text = f"{head}\n## Summary (`make bench`)\n\n{block}\n\n{sep.strip()} {rest}" if sep else f"{text}\n{block}\n"
    DOC.write_text(text, encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(SCRIPTS), help="run only these")
    parser.add_argument("--table-only", action="store_true", help="rewrite the table from the last results")
    args = parser.parse_args()
    started = time.monotonic()
    outcome = {} if args.table_only else run(args.only or [n for n in SCRIPTS if n not in ON_REQUEST])
    update_doc()
    print(table())
    print(f"\n{DOC} updated in {time.monotonic() - started:.0f} s")
    failed = {n: o for n, o in outcome.items() if o != "ok"}
    if failed:
        sys.exit(f"benchmarks that did not finish: {failed}")


if __name__ == "__main__":
    main()
