"""What python-rtmidi's JACK port costs the other JACK clients of its process: the `midi`
sink (rtmidi's JACK output) started and stopped beside `midi-in` or the `jack` adapter
(JACK-Client ports, whose process callback is Python) in one `sonibus run`.

python-rtmidi's calls keep the GIL while libjack waits for the server; opening and closing
a client changes JACK's graph, and the server waits for a cycle of every client before it
answers, the Python one too, whose callback waits for the GIL: nothing moves until JACK's
timeouts end the wait. Measured in the same run, each ``--times`` times, on a private JACK
server (dummy driver, 5.3 ms period): rtmidi's output opened (``MidiOut`` and its port) and
closed (``close_port``, ``delete``) with no other client in this process (the baseline),
then beside a JACK-Client client with a Python process callback (``alongside``), with the
longest gap between two of its cycles.

    .venv/bin/python bench/jack_rtmidi_stall.py [--times 5]

Writes bench/results/jack_rtmidi_stall.json and prints medians and ratios.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import jack
import rtmidi
from common import write
from midi_rate import start_jack, stop_jack


def open_and_close(cycles: list[float] | None) -> dict[str, float]:
    """rtmidi's JACK output opened and closed: seconds each, and the longest gap between two
    cycles of the Python client meanwhile (``cycles``: the times of its callbacks)."""
    started = time.monotonic()
    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "stall-out")
    out.open_virtual_port("out")
    opened = time.monotonic()
    time.sleep(0.2)
    closing = time.monotonic()
    out.close_port()
    out.delete()
    ended = time.monotonic()
    time.sleep(0.2)
    gaps = [b - a for a, b in itertools.pairwise(cycles) if b >= started] if cycles else []
    return {"open_s": opened - started, "close_s": ended - closing, "longest_gap_s": max(gaps, default=0.0)}


def python_client() -> tuple[Any, list[float]]:
    """A JACK client whose process callback is Python (as midi-in's and the jack adapter's)."""
    cycles: list[float] = []
    client = jack.Client("python-callback", no_start_server=True)
    client.midi_inports.register("in")

    def process(frames: int) -> None:
        cycles.append(time.monotonic())
        del cycles[:-2000]

    client.set_process_callback(process)
    client.activate()
    return client, cycles


def median(rows: list[dict[str, float]], field: str) -> float:
    return statistics.median(r[field] for r in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--times", type=int, default=5)
    args = parser.parse_args()
    jack.set_error_function(lambda text: None)
    jack.set_info_function(lambda text: None)
    server = start_jack(Path(tempfile.mkdtemp()) / "jackd.log")
    try:
        alone = [open_and_close(None) for _ in range(args.times)]
        client, cycles = python_client()
        time.sleep(0.5)
        try:
            alongside = [open_and_close(cycles) for _ in range(args.times)]
        finally:
            client.deactivate()
            client.close()
    finally:
        stop_jack(server)
    result = {"times": args.times, "alone": alone, "alongside": alongside, "summary": []}
    for field in ("open_s", "close_s"):
        a, b = median(alone, field), median(alongside, field)
        result["summary"].append({"scenario": f"(jack) rtmidi's JACK output, {field[:-2]}",
                                  "sonibus": f"{b * 1000:.0f} ms beside a Python JACK client",
                                  "baseline": f"{a * 1000:.0f} ms alone", "ratio": f"{b / a:.0f}×"})
    gap = median(alongside, "longest_gap_s")
    result["summary"].append({"scenario": "(jack) the Python client's longest gap between cycles meanwhile",
                              "sonibus": f"{gap * 1000:.0f} ms", "baseline": "5.3 ms (a period)",
                              "ratio": f"{gap / (256 / 48000):.0f}×"})
    for row in result["summary"]:
        print(f"{row['scenario']:<70} {row['sonibus']:>32}  {row['baseline']:>18}  {row['ratio']:>6}")
    print(f"wrote {write('jack_rtmidi_stall', result)}")


if __name__ == "__main__":
    main()
