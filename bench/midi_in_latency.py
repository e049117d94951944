"""``midi-in``'s JACK input: controller event → the node's worker has it, through the
JACK-Client port (``adapters/midi/jack_in.py``, as built) beside python-rtmidi's JACK
input (the path before issue 33 item 5), both in the same run on the same events.

A private JACK server with the dummy driver (``jackd --no-realtime ... -p 256``: a
5.3 ms period, so both paths carry up to a period of JACK's own delay) and a python-rtmidi
output ``sender:out`` in this process that sends control changes numbered by their two data
bytes, ``--rate`` a second. Both inputs are connected to it at once and put each message
in a ``SampleQueue`` as the node does; a consumer thread per path takes it out and notes the
time. What follows (the mapping, ``ask`` on the bus) is the same code on both paths.

    .venv/bin/python bench/midi_in_latency.py [--count 2000] [--rate 400]

Writes bench/results/midi_in_latency.json and prints p50/p99 in µs and their ratios.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from common import latency_stats, write
from midi_rate import start_jack, stop_jack


def consume(queue: Any, arrived: dict[int, float], count: int, stop: threading.Event) -> None:
    while len(arrived) < count and not stop.is_set():
        item = queue.get(timeout=0.1)
        if item is not None:
            message = item[1]
            arrived[(message[1] << 7) | message[2]] = time.perf_counter()


def summary(sent: dict[int, float], arrived: dict[int, float]) -> dict[str, float]:
    return latency_stats([arrived[n] - sent[n] for n in arrived if n in sent])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=2000, help="control changes sent (at most 16384)")
    parser.add_argument("--rate", type=float, default=400.0, help="a second")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="sb-midi-in-"))
    server = start_jack(folder / "jackd.log")
    import rtmidi

    from sonibus.adapters.midi import ports
    from sonibus.adapters.midi.jack_in import JackMidiIn
    from sonibus.bus.queue import SampleQueue
    sender = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "sender")
    stop = threading.Event()
    try:
        sender.open_virtual_port("out")
        queues = {"rtmidi": SampleQueue(4096), "jack_client": SampleQueue(4096)}
        old = ports.open_input("jack", "in", "sender:out",
                               lambda event, data=None: queues["rtmidi"].put(("midi", event[0])), client="old")
        new = JackMidiIn("new", "in", "sender:out", lambda message: queues["jack_client"].put(("midi", message)))
        arrived: dict[str, dict[int, float]] = {name: {} for name in queues}
        workers = [threading.Thread(target=consume, args=(queues[n], arrived[n], args.count, stop)) for n in queues]
        for worker in workers:
            worker.start()
        deadline = time.monotonic() + 5  # (rtmidi's open_port has connected when it returns)
        while not new.port.connections and time.monotonic() < deadline:
            time.sleep(0.01)
        sent: dict[int, float] = {}
        start = time.perf_counter()
        for n in range(args.count):
            time.sleep(max(0.0, start + n / args.rate - time.perf_counter()))
            sent[n] = time.perf_counter()
            sender.send_message([0xB0, n >> 7, n & 0x7F])
        deadline = time.monotonic() + 5
        while any(len(a) < args.count for a in arrived.values()) and time.monotonic() < deadline:
            time.sleep(0.05)
        stop.set()
        for worker in workers:
            worker.join()
        ports.close(old)
        new.close()
        result: dict[str, Any] = {"count": args.count, "rate": args.rate, "period_ms": 256 / 48,
                                  **{n: summary(sent, a) for n, a in arrived.items()}}
        result["ratio_p50"] = result["jack_client"]["p50_us"] / result["rtmidi"]["p50_us"]
        result["ratio_p99"] = result["jack_client"]["p99_us"] / result["rtmidi"]["p99_us"]
        for name in queues:
            row = result[name]
            print(f"{name:<12} received {row['n']:>6}  p50 {row['p50_us']:>7.0f} µs  p99 {row['p99_us']:>7.0f} µs"
                  f"  max {row['max_us']:>7.0f} µs")
        print(f"JACK-Client / rtmidi: p50 {result['ratio_p50']:.2f}, p99 {result['ratio_p99']:.2f}")
        write("midi_in_latency", result)
    finally:
        stop.set()
        sender.delete()
        stop_jack(server)


if __name__ == "__main__":
    main()
