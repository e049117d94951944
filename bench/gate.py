"""What the message layer's gate costs a sink per message, beside decoding alone.

Three ways to take the same payloads, interleaved in rounds so a noisy machine
hurts them alike: ``msgpack.unpackb`` alone (the baseline: what any sink must
do), ``Gate.check`` (decode and check), and ``Selection.incoming`` (check, then
pick a sink's joints out of a frame, as the OSC and MIDI sinks do). Payloads:
Pepper frames of 17 joints, a joint sample, an event.

    .venv/bin/python bench/gate.py [--messages 20000]
"""

from __future__ import annotations

import argparse
import gc
import time
from collections.abc import Callable

import msgpack
import numpy as np
from common import write

from sonibus.bus import framing, keys, load_model, messages
from sonibus.bus.codec import encode
from sonibus.bus.keys import Key
from sonibus.bus.streams import Selection

MODEL = load_model("pepper")
ROUNDS = 10


def payloads(n: int) -> dict[str, tuple[Key, list[bytes]]]:
    t0 = time.time() - n / 100 - 10  # every t in the past
    rng = np.random.default_rng(1)
    values = rng.uniform(-1.0, 1.0, (n, len(MODEL.joint_names)))
    return {
        "frame": (Key.parse(keys.frame("pepper")),
                  [encode(framing.frame(t0 + k / 100, k, MODEL.joint_names, values[k].tolist())) for k in range(n)]),
        "joint sample": (Key.parse(keys.joint("pepper", "HeadYaw")),
                         [encode({"t": t0 + k / 100, "seq": k, "v": float(values[k, 0])}) for k in range(n)]),
        "event": (Key.parse(keys.event("pepper", "behavior")),
                  [encode({"t": t0 + k / 100, "kind": "behavior", "name": f"animations/Stand/Gestures/Hey_{k % 5}",
                           "state": "started"}) for k in range(n)]),
    }


def timed(take: Callable[[bytes], object], data: list[bytes]) -> list[float]:
    out = []
    clock = time.perf_counter_ns
    for payload in data:
        started = clock()
        take(payload)
        out.append(clock() - started)
    return out


def stats(ns: list[float]) -> dict[str, float]:
    a = np.array(ns) / 1000.0
    return {"n": len(a), "p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=20_000)
    args = parser.parse_args()
    result: dict = {"messages": args.messages, "rounds": ROUNDS, "kinds": {}, "summary": []}
    gate, selection = messages.Gate(), Selection([keys.joints("pepper"), keys.event("pepper", "*")])
    for kind, (key, data) in payloads(args.messages).items():
        ways: dict[str, Callable[[bytes], object]] = {
            "decode_only": lambda p: msgpack.unpackb(p, raw=False, strict_map_key=False),
            "gate": lambda p, key=key: gate.check(key, p),
            "gate_and_select": lambda p, key=key: selection.incoming(key.key, p),
        }
        times: dict[str, list[float]] = {way: [] for way in ways}
        chunk = len(data) // ROUNDS
        gc.disable()
        for r in range(ROUNDS):
            part = data[r * chunk:(r + 1) * chunk]
            for way, take in ways.items():
                times[way] += timed(take, part)[10:]  # warm each round's first calls
        gc.enable()
        figures = {way: stats(ns) for way, ns in times.items()}
        result["kinds"][kind] = figures
        base, checked, full = figures["decode_only"], figures["gate"], figures["gate_and_select"]
        result["summary"].append({
            "scenario": f"gate per {kind}, p50 / p99",
            "sonibus": f"{checked['p50_us']:.1f} / {checked['p99_us']:.1f} µs (with a sink's selection "
                       f"{full['p50_us']:.1f} / {full['p99_us']:.1f} µs)",
            "baseline": f"{base['p50_us']:.1f} / {base['p99_us']:.1f} µs (msgpack decode only)",
            "ratio": f"{checked['p50_us'] / base['p50_us']:.1f}×",
        })
        print(f"{kind:>13}: decode {base['p50_us']:.2f} µs, gate {checked['p50_us']:.2f} µs "
              f"({checked['p50_us'] / base['p50_us']:.1f}×), gate and selection {full['p50_us']:.2f} µs; "
              f"p99 {base['p99_us']:.2f} / {checked['p99_us']:.2f} / {full['p99_us']:.2f} µs")
    write("gate", result)


if __name__ == "__main__":
    main()
