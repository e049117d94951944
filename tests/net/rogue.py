"""A rogue participant, run from inside a test's network namespace: it claims a robot
as if it had done so an hour ago (a time that makes sense, so it wins the one-owner rule
on a bus without access control), puts frames of that robot with HeadYaw at ``--angle``,
and answers the robot's commands itself, for ``--seconds``; then prints one JSON line of
what it sent.

    ip netns exec NS python tests/net/rogue.py pepper --config show.toml --host sound-pc
"""

from __future__ import annotations

import argparse
import json
import time
from contextlib import closing

import zenoh

from sonibus.bus import encode, keys, open_session
from sonibus.bus.cli.api import add_bus_arguments, bus_config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("robot")
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--angle", type=float, default=2.0)
    add_bus_arguments(parser)
    args = parser.parse_args()
    asked = []
    with closing(open_session(bus_config(args))) as session:
        since = int(time.time() * 1000) - 3_600_000
        token = session.liveliness().declare_token(f"{keys.ROBOTS}/{args.robot}/{since}/rogue/x")

        def answer(query: zenoh.Query) -> None:
            asked.append(str(query.key_expr))
            query.reply(keys.command(args.robot, "stop"), encode({"ok": True, "verb": "stop", "result": {}}))
        queryable = session.declare_queryable(keys.command(args.robot), answer)
        frames = 0
        ends = time.monotonic() + args.seconds
        while time.monotonic() < ends:
            session.put(keys.frame(args.robot), encode({"t": time.time(), "seq": 10**9 + frames, "names": ["HeadYaw"],
                                                         "v": [args.angle]}))
            frames += 1
            time.sleep(0.02)
        queryable.undeclare()
        token.undeclare()
    print(json.dumps({"frames": frames, "commands_asked": asked}), flush=True)


if __name__ == "__main__":
    main()
