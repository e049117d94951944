"""A soak of the bus under bad input: the fuzz suite of ``tests/fuzz`` (every
family — frames, joint samples, derived values, events, commands, info queries
and garbage info replies, OSC packets, HTTP and WebSocket to the three servers —
valid, malformed and hostile, the huge frames of issue 13, a flood of 300 of them
each round, and bursts at up to 5000 inputs/s) against one ``sonibus run`` holding
every built-in node, again and again with fresh random inputs for ``--minutes``,
then the same checks as the test: every node running and every server serving a
new client after each family, data flowing again at its normal rate to every
sink, no command from invalid input, RSS growth under 150 MB, and the recording
passing ``info``, ``export``, a full read and ``replay``.

    .venv/bin/python bench/soak.py [--minutes 3]

Writes bench/results/soak.json (counts per family, the nodes' own counters,
rates before and after, RSS, and every problem found) and prints a summary.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from common import write

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the tests package, for its fuzzer

from tests.fuzz.campaign import CI, campaign
from tests.fuzz.show import Show


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0, help="how long to fuzz (default: 3)")
    args = parser.parse_args()
    plan = replace(CI, derandomize=False, seconds=args.minutes * 60)  # CI's families, fresh inputs, for longer
    tmp = Path(tempfile.mkdtemp(prefix="soak-"))
    with Show(tmp) as show:
        report = campaign(show, plan, tmp / "fuzz.json")
    found = json.loads((tmp / "fuzz.json").read_text())
    if report.problems:
        print(f"the recording and the log are kept in {tmp}")
    else:
        shutil.rmtree(tmp)
    tried = sum(t["total"] for t in found["counts"]["tried"].values())
    executed = found["counts"]["commands_from_invalid_input"]
    rss = found["figures"].get("rss_mb", {})
    result = {
        "machine": f"{platform.node()} {platform.machine()}",
        "minutes": args.minutes,
        **found,
        "summary": [
            {"scenario": f"soak: bus fuzz for {found['figures'].get('fuzz_s', 0) / 60:.1f} min, every built-in node",
             "sonibus": f"{tried:,} inputs, {len(report.problems)} problem(s)", "goal": "no problem",
             "met": "yes" if not report.problems else "no"},
            {"scenario": "soak: commands run from invalid input", "sonibus": str(executed), "goal": "0",
             "met": "yes" if executed == 0 else "no"},
            {"scenario": "soak: RSS growth of sonibus run", "sonibus": f"{rss.get('growth', '?')} MB",
             "baseline": f"{rss.get('before', '?')} MB at start", "goal": "< 150 MB",
             "met": "yes" if isinstance(rss.get("growth"), float) and rss["growth"] < 150 else "no"},
        ],
    }
    print(f"results in {write('soak', result)}")
    for problem in report.problems:
        print(f"  problem: {problem}")


if __name__ == "__main__":
    main()
