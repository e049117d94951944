"""One fuzzing campaign against a ``Show``: every family in turn (Hypothesis), the
huge frames of issue 13, bursts at high rate, then every check of ``checks``.
Shared by ``tests/fuzz/test_bus_fuzz.py`` (about a minute) and ``bench/soak.py``
(minutes)."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from . import checks
from .families import FAMILIES, ROBOT, VALID, Input, bursts, flood, huge_frame, issue_inputs, pack, signature
from .fuzzer import BURST_RATE, Fuzzer
from .rogue import ROGUE_FAMILIES, claim_flood, stats_flood
from .server_http import HttpFamily
from .server_ws import WebSocketFamily
from .serving import no_server_errors, serving
from .show import Show

# Commands that undo what valid fuzz commands may have left (a posture or a joint held, a
# behavior), sent as valid input before the flow is measured: the idle robot breathes again
# (a stop holds it still until its next move: the posture is that move), so its joints change
# every frame and the MIDI sink (which sends changes only) has something to send.
RESET = (("stop", {}), ("stiffness", {"names": ["Body"], "value": 1.0}), ("awareness", {"enabled": True}),
         ("posture", {"name": "StandInit", "speed": 1.0}))


@dataclass(frozen=True)
class Plan:
    examples: dict[str, int]      # family → Hypothesis examples
    huge_frames: int = 10         # frames of 50,000 joints
    huge_flood: int = 0           # more of them, at up to BURST_RATE (about 1 MB each: the memory bound's test)
    made_up: int = 1200           # robots claimed at once, and nodes' stats (past every cap: 1,024 robots, 128 nodes)
    bursts: int = 8               # bursts of 500-2000 inputs at up to 5000/s
    derandomize: bool = True      # the same inputs every run (CI)
    rounds: int = 1               # the whole sequence of families, at least this often
    seconds: float = 0.0          # and again until this long has been fuzzed (soak)


CI = Plan(examples={"frame": 300, "joint": 200, "derived": 150, "event": 150, "command": 150, "info": 60,
                    "osc": 300, "claim": 40, "stats": 40, "http": 80, "websocket": 60}, huge_flood=300)
SERVER_FAMILIES = (HttpFamily, WebSocketFamily)  # the web pages', OSCQuery's and Foxglove's servers


def _run(fuzzer: Fuzzer, strategy: st.SearchStrategy[Any], examples: int, derandomize: bool,
         action: Any) -> None:
    @settings(max_examples=examples, deadline=None, derandomize=derandomize, database=None,
              phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))
    @given(strategy)
    def each(value: Any) -> None:
        action(value)

    each()


def _reset(fuzzer: Fuzzer) -> None:
    for verb, args in RESET:
        fuzzer.send(Input("command", VALID, "query", f"{ROBOT}/cmd/{verb}", pack(args), signature(verb, args),
                          note="reset"))


def _after(fuzzer: Fuzzer, report: checks.Report, before: dict[str, float], family: str) -> None:
    """After a family: alive, every node running, each server serving a new client, data flowing
    again to the OSC targets and MIDI."""
    fuzzer.release()
    _reset(fuzzer)
    ended = time.monotonic()
    checks.alive(fuzzer.show, report, f"after {family}")
    serving(fuzzer.show, report, f"after {family}")  # (within the wait of flowing's window)
    checks.flowing(fuzzer.show, report, before, ended, f"after {family}")


def _rogue_floods(fuzzer: Fuzzer, report: checks.Report, before: dict[str, float], count: int) -> None:
    """Issue 26's floods: ``count`` made-up robots claimed at once (STOP still answered while
    they are), and ``count`` made-up nodes' stats of ~16 KB."""
    claimed, flooded = claim_flood(count), stats_flood(count)
    fuzzer.burst(claimed, len(claimed))
    checks.stop_works(fuzzer, report, f"with {len(claimed)} made-up robots claimed")
    fuzzer.burst(flooded, len(flooded))  # (the robots still claimed)
    checks.stop_works(fuzzer, report, f"with {len(flooded)} made-up nodes' stats too")
    _after(fuzzer, report, before, f"{count} made-up robots and nodes")


def campaign(show: Show, plan: Plan, out: Path) -> checks.Report:
    """Fuzz ``show`` by ``plan``; every check; counts and figures written to ``out`` (JSON)."""
    report = checks.Report()
    fuzzer = Fuzzer(show)
    started = time.monotonic()
    try:
        checks.alive(show, report, "start")
        serving(show, report, "start")
        before = checks.baseline(show)
        rss_before = show.rss.now() if show.rss else 0
        fuzz_started = time.monotonic()
        burst_rates: list[float] = []
        rounds = 0
        while rounds < plan.rounds or time.monotonic() - fuzz_started < plan.seconds:
            rounds += 1
            for family, strategy in {**FAMILIES, **ROGUE_FAMILIES}.items():
                for item in issue_inputs(family):  # each on its own: a later input must not mask an earlier one
                    fuzzer.send(item)
                    _after(fuzzer, report, before, f"{family} input of {item.note}")
                _run(fuzzer, strategy(), plan.examples[family], plan.derandomize, fuzzer.send)
                _after(fuzzer, report, before, family)
            for server_family in SERVER_FAMILIES:
                family_started = time.monotonic()
                with server_family(fuzzer, report) as each:
                    _run(fuzzer, each.strategy(), plan.examples[each.name], plan.derandomize, each.send)
                    each.scripted()
                _after(fuzzer, report, before, each.name)
                spent = report.figures.setdefault("server_families_s", {})
                spent[each.name] = round(spent.get(each.name, 0.0) + time.monotonic() - family_started, 1)
            for _ in range(plan.huge_frames):
                fuzzer.send(huge_frame())
            _after(fuzzer, report, before, "huge frames")
            if plan.huge_flood:
                fuzzer.burst(huge_frame(), plan.huge_flood)
                _after(fuzzer, report, before, f"a flood of {plan.huge_flood} huge frames")
            _rogue_floods(fuzzer, report, before, plan.made_up)
            frames = flood()
            burst_rates.append(fuzzer.burst(frames, len(frames)))
            _after(fuzzer, report, before, f"a {frames[0].note} at {BURST_RATE}/s")
            _run(fuzzer, bursts(), plan.bursts, plan.derandomize, lambda b: burst_rates.append(fuzzer.burst(*b)))
            _after(fuzzer, report, before, "bursts")
        _reset(fuzzer)
        report.figures["rounds"] = rounds
        report.figures["midi_reader_deaths"] = show.midi.deaths if show.midi else []  # (the test's, restarted)
        report.figures["burst_rate_per_s"] = round(min(burst_rates, default=0.0))
        fuzzer.settle()
        ended = time.monotonic()
        report.figures["fuzz_s"] = round(ended - fuzz_started, 1)
        checks.alive(show, report, "end")
        checks.flow(show, report, before, ended)
        checks.commands(fuzzer.oracle, report)
        checks.memory(show, report, rss_before, fuzz_started)
    finally:
        fuzzer.close()
    checks.stopped(show, report)
    no_server_errors(report)
    checks.recording(show, report)
    report.figures["total_s"] = round(time.monotonic() - started, 1)
    write(report, fuzzer, out)
    return report


def counts(fuzzer: Fuzzer, report: checks.Report) -> dict[str, Any]:
    """Per family: inputs tried by label, what came back, and what the nodes counted."""
    node_counters = report.figures.get("node_counters", {})
    refused = {node: {k: v for k, v in c.items() if k in ("bad", "malformed", "bad_args", "unknown_address",
                                                          "stale", "late", "dropped", "busy", *SERVER_COUNTERS)}
               for node, c in node_counters.items()}
    return {
        "tried": {family: dict(labels) | {"total": sum(labels.values())} for family, labels in fuzzer.tried.items()},
        "outcomes": {family: dict(c) for family, c in fuzzer.outcomes.items()},
        "osc_replies": dict(fuzzer.osc_replies),
        "ghost_info_queries": sum(fuzzer.ghost_queries.values()),
        "valid_commands_sent": dict(fuzzer.oracle.sent_valid),
        "commands_executed": dict(fuzzer.oracle.executed),
        "commands_from_invalid_input": len(fuzzer.oracle.unexpected),
        "counted_bad_by_node": refused,
        "recording_stats": (report.figures.get("recording") or {}).get("stats"),
    }


SERVER_COUNTERS = ("refused", "timed_out", "idle_closed", "connections_refused", "clients_refused", "accept_failed",
                   "errors", "ws_dropped", "dropped_for_clients")


def write(report: checks.Report, fuzzer: Fuzzer, out: Path) -> None:
    summary = {"ok": not report.problems, "problems": report.problems, "counts": counts(fuzzer, report),
               "figures": report.figures,
               "unexpected_commands": [json.loads(json.dumps(e, default=repr)) for e in fuzzer.oracle.unexpected],
               "first_inputs": {k: v.describe() for k, v in sorted(fuzzer.first.items())}}
    out.write_text(json.dumps(summary, indent=2, default=repr) + "\n")
    tried = {family: t["total"] for family, t in summary["counts"]["tried"].items()}
    per_family = ", ".join(f"{family} {n}" for family, n in tried.items())
    print(f"\nbus fuzz: {sum(tried.values())} inputs ({per_family}); "
          f"bad counted {_bad_total(summary['counts']['counted_bad_by_node'])}; "
          f"commands executed {sum(fuzzer.oracle.executed.values())}, from invalid input "
          f"{len(fuzzer.oracle.unexpected)}; RSS +{report.figures.get('rss_mb', {}).get('growth', '?')} MB; "
          f"{len(report.problems)} problem(s); {out}")


def _bad_total(by_node: dict[str, dict[str, int]]) -> str:
    parts = [f"{node} {sum(v for k, v in c.items() if k in ('bad', 'malformed', 'bad_args'))}"
             for node, c in sorted(by_node.items())]
    return ", ".join(parts) or "nothing (no counters in the log)"
