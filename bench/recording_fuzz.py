"""Recordings from strangers (issue 33): a campaign of the crafted-file fuzz of
``tests/recorder/fuzz_files.py`` (the suite runs 60 files; this runs ``--files``
of fresh seeds, ``info``, ``export``, ``recover`` and ``plot`` on each, in a
child process whose peak RSS is read), and what checking every message like the
gate costs a reading: messages/s of ``Recording.messages`` beside mcap's own
reader decoding the same JSON (the baseline, what reading cost before), in rounds.

    .venv/bin/python bench/recording_fuzz.py [--files 1500] [--messages 200000]

Writes bench/results/recording_fuzz.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import write

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the tests package, for the fuzz

CAMPAIGN = """
import json, sys, tempfile, time
from pathlib import Path
from tests.recorder.fuzz_files import COMMANDS, judge, mutants
seed, count = int(sys.argv[1]), int(sys.argv[2])
wrong, started = [], time.monotonic()
with tempfile.TemporaryDirectory() as folder:
    for n, (kind, path) in enumerate(mutants(seed, count, Path(folder))):
        wrong += judge(path, (*COMMANDS, "plot") if n % 10 == 0 else COMMANDS)
        for made in Path(folder).iterdir():
            if made.is_file():
                made.unlink()
with open("/proc/self/status") as f:
    peak = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 1024
print(json.dumps({"files": count, "wrong": wrong, "seconds": time.monotonic() - started, "peak_mb": peak}))
"""


def campaign(files: int, seed: int) -> dict:
    done = subprocess.run([sys.executable, "-c", CAMPAIGN, str(seed), str(files)], cwd=ROOT, capture_output=True,
                          text=True, timeout=3600, check=True)
    return json.loads(done.stdout)


def reading_rates(messages: int, rounds: int) -> dict:
    from mcap.reader import make_reader

    from sonibus.adapters.recorder import Recording
    from sonibus.adapters.recorder.writer import RecordingWriter

    folder = tempfile.mkdtemp()
    path = f"{folder}/read.mcap"
    t0 = time.time() - messages / 1000 - 60
    with RecordingWriter(path) as out:
        for n in range(messages):
            out.write(f"pepper/joints/J{n % 17}", int((t0 + n / 1000) * 1e9), {"t": t0 + n / 1000, "seq": n // 17,
                                                                             "v": 0.001 * (n % 997)})

    def ours() -> int:
        with Recording(path) as recording:
            return sum(1 for _ in recording.messages())

    def baseline() -> int:
        with open(path, "rb") as f:
            return sum(1 for _, _, m in make_reader(f).iter_messages(log_time_order=False) if json.loads(m.data))

    found: dict[str, list[float]] = {"ours": [], "baseline": []}
    for _ in range(rounds):
        for name, read in (("baseline", baseline), ("ours", ours)):
            started = time.perf_counter()
            assert read() == messages
            found[name].append(messages / (time.perf_counter() - started))
    return {name: {"median_per_s": statistics.median(rates), "min_per_s": min(rates)} for name, rates in found.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", type=int, default=1500, help="crafted files (default: 1500)")
    parser.add_argument("--messages", type=int, default=200_000, help="messages in the reading test (default: 200000)")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    seed = int(time.time())
    fuzz = campaign(args.files, seed)
    rates = reading_rates(args.messages, args.rounds)
    ratio = rates["ours"]["median_per_s"] / rates["baseline"]["median_per_s"]
    result = {
        "machine": platform.node(), "seed": seed, "fuzz": fuzz, "reading": rates,
        "summary": [
            {"scenario": f"crafted recordings (issue 33): {fuzz['files']} files, info/export/recover (+plot)",
             "sonibus": f"{len(fuzz['wrong'])} internal errors, peak {fuzz['peak_mb']:.0f} MB, "
                        f"{fuzz['files'] / fuzz['seconds']:.0f} files/s",
             "goal": "none; < 200 MB", "met": "yes" if not fuzz["wrong"] and fuzz["peak_mb"] < 200 else "no"},
            {"scenario": "reading a recording, every message checked like the gate (median msg/s)",
             "sonibus": f"{rates['ours']['median_per_s']:,.0f}/s",
             "baseline": f"{rates['baseline']['median_per_s']:,.0f}/s (mcap's reader + json)",
             "ratio": f"{ratio:.2f}×", "goal": "", "met": ""},
        ],
    }
    write("recording_fuzz", result)
    print(json.dumps(result["summary"], indent=2))
    for line in fuzz["wrong"][:20]:
        print(line)


if __name__ == "__main__":
    main()
