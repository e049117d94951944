"""A live robot's table, as ``sonibus info ROBOT`` prints it: model, owner, rate,
joints with limits and units, behaviors, postures, derived values.

>>> info = {"robot": "toy", "model": "pepper", "rate_hz": 50.0, "adapter": "sim", "behaviors": ["wave"],
...         "postures": [], "owner": {"host": "pc", "node": "sim-toy"},
...         "joints": [{"name": "HeadYaw", "unit": "rad", "min": -2.0857, "max": 2.0857, "max_velocity": 7.34,
...                     "chain": "Head"}], "connection": {"state": "connected", "frames_per_s": 49.8}}
>>> print("\\n".join(table(info)))
toy: pepper, connected, 50 frames/s, owned by sim-toy on pc (adapter sim)
  joint           unit            min        max  max speed  chain
  HeadYaw         rad         -2.0857     2.0857     7.34/s  Head
  behaviors (1):
    wave
  postures (0): none
  derived values: none (no features node serves them)
"""

from __future__ import annotations

import argparse
import json
import queue
from typing import Any

from .. import connection
from ..info import InfoRequests
from .api import Environment, Exit, bus_config
from .hints import not_found, reach_hint, robots_hint, searching


def table(info: dict[str, Any]) -> list[str]:
    """The lines of a robot's info (merged with its derived values, ``bus/info.py``)."""
    owner = info.get("owner", {})
    state = connection.state_of(info)
    rate = connection.rate(info)
    asked = f" (of {info['rate_hz']:g} asked)" if state["state"] != "connected" or rate < 0.9 * info["rate_hz"] else ""
    lines = [f"{info['robot']}: {info['model']}, {connection.describe(state)}, {rate:.0f} frames/s{asked}, owned by "
             f"{owner.get('node', '?')} on {owner.get('host', '?')} (adapter {info.get('adapter', '?')})",
             f"  {'joint':<15} {'unit':<8} {'min':>10} {'max':>10} {'max speed':>10}  chain"]
    for joint in info["joints"]:
        lines.append(f"  {joint['name']:<15} {joint['unit']:<8} {joint['min']:>10.5g} {joint['max']:>10.5g} "
                     f"{joint['max_velocity']:>8.4g}/s  {joint.get('chain', '')}".rstrip())
    lines.append(f"  behaviors ({len(info['behaviors'])}):" + "".join(f"\n    {b}" for b in info["behaviors"]))
    lines.append(f"  postures ({len(info['postures'])}): {', '.join(info['postures']) or 'none'}")
    derived = info.get("derived", [])
    if not derived:
        lines.append("  derived values: none (no features node serves them)")
    else:
        lines.append(f"  derived values ({len(derived)}):")
        for d in derived:
            span = f"{d['min']:.4g}..{d['max']:.4g}" if "min" in d else ""
            lines.append(f"    {d['key']:<40} {d['unit']:<10} {span}".rstrip())
    for feature, why in info.get("unavailable", {}).items():
        lines.append(f"  not derived: {feature}: {why}")
    return lines


def show(robot: str, args: argparse.Namespace, env: Environment, as_json: bool = False, timeout: float = 2.0) -> Exit:
    """Print ``robot``'s table (or its info as JSON), asking the bus; ``RobotNotFound``
    with the robots there are when nobody answers for it."""
    cfg = bus_config(args)
    answers: queue.Queue[dict[str, Any] | str] = queue.Queue()
    with searching(cfg, robot) as (bus, reached):
        requests = InfoRequests(bus, lambda _, info: answers.put(info), lambda _, error: answers.put(error),
                                retry_s=timeout)
        requests.ask(robot)
        try:
            info = answers.get(timeout=timeout + 1.0)
        except queue.Empty:
            info = None
        if not isinstance(info, dict):
            raise not_found(robot, robots_hint(bus, robot) if reached else reach_hint(cfg, reached, "nothing found"),
                            info or "")
    env.say(json.dumps(info, indent=2) if as_json else "\n".join(table(info)))
    return Exit.OK
