"""Stop every robot of a bus as the web page's STOP and ``sonibus top``'s ``s`` do
(``client.stop_all``), from inside a test's network namespace; print what came back as one
JSON line: ``{"answered": {robot: "ok" | error}, "silent": [robots], "error": code}``.

    ip netns exec NS python tests/net/stop_all.py --config show.toml --host alice

Takes the bus options of every command (``--config``, ``--connect``, ``--no-multicast``...).
It waits until it has seen a robot's claim (at most ``--wait`` s) so the robots on the bus
are known when the stop ends."""

from __future__ import annotations

import argparse
import json
import threading
import time
from contextlib import closing

from sonibus.bus import Bus, CommandError, open_session
from sonibus.bus.claimwatch import owners
from sonibus.bus.cli.api import add_bus_arguments, bus_config
from sonibus.bus.client import stop_all


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    add_bus_arguments(parser)
    parser.add_argument("--wait", type=float, default=10.0, help="seconds to wait for a robot's claim")
    args = parser.parse_args()
    answered: dict[str, str] = {}
    ended = threading.Event()
    silent: list = []
    with closing(open_session(bus_config(args))) as session:
        bus = Bus(session, node="stop-all")
        deadline = time.monotonic() + args.wait
        while not owners(bus).robots() and time.monotonic() < deadline:
            time.sleep(0.05)

        def done(robot: str, outcome: dict | CommandError) -> None:
            answered[robot] = f"{outcome.code}: {outcome.message}" if isinstance(outcome, CommandError) else "ok"

        def left(robots: list[str], error: CommandError) -> None:
            silent.extend([robots, error.code])
            ended.set()
        stop_all(bus, done, left, timeout=5.0)
        ended.wait(10.0)
    print(json.dumps({"answered": answered, "silent": silent[0] if silent else None,
                      "error": silent[1] if silent else "no end"}), flush=True)


if __name__ == "__main__":
    main()
