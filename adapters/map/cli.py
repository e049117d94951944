"""``sonibus map``: every map of the bus's map nodes with its live input and output,
refreshed in the terminal (each node's ``<node>/maps/list``).

    $ sonibus map --count 1
    sound/cutoff  pepper/derived/hand/R.z      in 0.412 ▕████▏     ▏  out 515.825 Hz  [200, 2000] exp
    sound/swing   pepper/derived/hand_speed/R  in 0.020 ▕▏         ▏  out 0.02        [0, 1] linear  SILENT

``sonibus map add NODE MAP 'key = value' ...`` adds a map while the node runs (each argument a
line of its table, as in the installation file); ``sonibus map remove NODE MAP`` takes one out.
"""

from __future__ import annotations

import argparse
import json
import tomllib
from typing import Any

from sonibus.bus import keys
from sonibus.bus.cli.api import Command, Environment, Exit, bus_config, joined
from sonibus.bus.cli.hints import reach_hint
from sonibus.bus.client import ask_key
from sonibus.bus.errors import CommandError, ConfigError

from .resume import asked

BAR = 10          # characters of an input's bar
PARTS = " ▏▎▍▌▋▊▉█"  # eighths of a character


CHANGES = ("add", "remove")  # the first word that makes `sonibus map` change a node's maps


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("node", nargs="?", default="*", metavar="NODE",
                   help="one map node (default: every one); or add NODE MAP 'key = value'..., remove NODE MAP")
    p.add_argument("words", nargs="*", metavar="...", help=argparse.SUPPRESS)
    p.add_argument("--count", type=int, metavar="N", help="print the maps N times, then exit (default: until Ctrl-C)")
    p.add_argument("--interval", type=float, default=0.5, metavar="S", help="seconds between two views (0.5)")
    p.add_argument("--timeout", type=float, default=1.0, metavar="S", help="seconds to wait for the nodes' answers")


def _map(args: argparse.Namespace, env: Environment) -> Exit:
    if args.node in CHANGES:
        return _change(args, env)
    if args.words:
        raise ConfigError(f"map: unexpected {' '.join(args.words)!r} — list with `sonibus map [NODE]`, change with "
                          "`sonibus map add NODE MAP 'key = value'...` or `sonibus map remove NODE MAP`")
    if args.node != "*":
        try:
            keys.check_name("node", args.node)
        except ValueError as exc:
            raise ConfigError(f"map: {exc}") from None
    if not args.interval > 0 or not args.timeout > 0 or (args.count is not None and args.count < 1):
        raise ConfigError("map: --interval and --timeout must be more than 0, --count at least 1")
    cfg = bus_config(args)
    shown = 0
    with joined(cfg) as bus:
        reached = bus.discover()
        while not env.stop.is_set() and (args.count is None or shown < args.count):
            answers = [a["result"] for a in bus.query(keys.maps(args.node, "list"), {}, timeout=args.timeout)
                       if a.get("ok")]
            if not answers:
                env.hint(reach_hint(cfg, reached, f"no map node answered on {keys.maps(args.node, 'list')}"))
                return Exit.NOT_FOUND
            if shown:
                env.say("")
            for line in lines(answers):
                env.say(line)
            shown += 1
            if args.count is None or shown < args.count:
                env.stop.wait(args.interval)
    return Exit.OK


def request(verb: str, words: list[str]) -> tuple[str, dict[str, Any]]:
    """The node and the request of ``sonibus map add|remove`` with ``words``; ``ConfigError`` in one line.

    >>> request("add", ["sound", "swing", 'source = "pepper/joints/HeadYaw"', "to = [0, 10]"])
    ('sound', {'map': 'swing', 'table': {'source': 'pepper/joints/HeadYaw', 'to': [0, 10]}})
    >>> request("remove", ["sound", "swing"])
    ('sound', {'map': 'swing'})
    """
    usage = "give NODE MAP 'key = value'..." if verb == "add" else "give NODE MAP"
    if len(words) < 2 or (verb == "remove" and len(words) != 2) or (verb == "add" and len(words) < 3):
        raise ConfigError(f"map {verb}: {usage} (got {len(words)} word{'s' if len(words) != 1 else ''})")
    node, name = words[0], words[1]
    try:
        keys.check_name("node", node)
    except ValueError as exc:
        raise ConfigError(f"map {verb}: {exc}") from None
    if verb == "remove":
        return node, {"map": name}
    try:
        table = tomllib.loads("\n".join(words[2:]))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"map add: the map's table is not TOML ({exc}) — give each step as its own argument, "
                          "'to = [0, 10]', strings quoted: 'source = \"pepper/joints/HeadYaw\"'") from None
    return node, {"map": name, "table": table}


def _change(args: argparse.Namespace, env: Environment) -> Exit:
    node, message = request(args.node, args.words)
    key = keys.maps(node, args.node)
    nobody = CommandError("not_found", f"{args.node}: no map node '{node}' on the bus ({key} is served by nothing)")
    env.say(json.dumps(asked(args, key, node, lambda bus, done: ask_key(bus, key, message, done, args.timeout, nobody,
                                                                         f"map node '{node}'"))))
    return Exit.OK


def lines(answers: list[dict[str, Any]]) -> list[str]:
    """One line per map of each node's ``list`` answer, nodes and maps in name order.

    >>> print(lines([{"node": "sound", "maps": [{"name": "cutoff", "enabled": True, "unit": "Hz",
    ...     "to": [200, 2000], "input": 0.5, "output": 632.456, "silent": False, "learning": None,
    ...     "table": {"source": "pepper/derived/hand/R.z", "curve": "exp"}}]}])[0])
    sound/cutoff  pepper/derived/hand/R.z  in 0.500 ▕█████     ▏  out 632.456 Hz  [200, 2000] exp
    """
    rows = []
    for answer in sorted(answers, key=lambda a: str(a.get("node"))):
        for m in sorted(answer.get("maps", ()), key=lambda m: str(m.get("name"))):
            table = m.get("table", {})
            source = table.get("source") or ", ".join(f"{k}={v}" for k, v in (table.get("sources") or {}).items())
            curve = table.get("curve", "points" if "points" in table else "linear")
            x, y = m.get("input"), m.get("output")
            shown_in = f"in {x:.3f} {_bar(x)}" if isinstance(x, int | float) else f"in {'—':>5} {_bar(None)}"
            shown_out = f"out {y:.6g} {m.get('unit', '')}".rstrip() if isinstance(y, int | float) else "out —"
            low, high = m.get("to", ("?", "?"))
            state = "" if m.get("enabled", True) else "  DISABLED"
            if m.get("silent"):
                state += "  SILENT"
            if m.get("learning"):
                state += f"  LEARNING {m['learning'].get('source')} ({m['learning'].get('seconds'):g} s)"
            rows.append([f"{answer.get('node')}/{m.get('name')}", source, shown_in, shown_out,
                         f"[{low:g}, {high:g}] {curve}{state}"])
    widths = [max((len(r[i]) for r in rows), default=0) for i in range(4)]
    return ["  ".join(c.ljust(w) for c, w in zip(r[:4], widths, strict=True)) + "  " + r[4] for r in rows]


def _bar(x: float | None) -> str:
    """A fraction 0..1 as a bar of ``BAR`` characters, in eighths."""
    if x is None:
        return "▕" + " " * BAR + "▏"
    eighths = round(max(0.0, min(1.0, x)) * BAR * 8)
    full, part = divmod(eighths, 8)
    return "▕" + ("█" * full + (PARTS[part] if part else "")).ljust(BAR) + "▏"


MAP = Command("map", "list the map nodes' maps with their live values; add or remove one", _arguments, _map,
              bus=True)
