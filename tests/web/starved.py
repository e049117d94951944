"""A web server (the test plug-in's ``ws-value`` node) in a process that has used up
its files: run by tests/web/test_limits.py. It prints its port, takes every file it
may open, says ``starved``, waits for a line on stdin, gives the files back, says
``fed``, waits for another line and prints the node's state and counters."""

from __future__ import annotations

import os
import sys

from sonibus_testplugin.ws_value import ValueServer, ValueServerConfig

from tests.conftest import Network


def main() -> None:
    net = Network()
    try:
        server = net.start(ValueServer(ValueServerConfig(robot="nobody", port=0), name="web"))
        print(server.web.port, flush=True)
        hog = []
        try:
            while True:
                hog.append(os.open(os.devnull, os.O_RDONLY))
        except OSError:
            pass
        print("starved", flush=True)
        sys.stdin.readline()
        for fd in hog:
            os.close(fd)
        print("fed", flush=True)
        sys.stdin.readline()
        print(server.state, server.stats["accept_failed"], flush=True)
    finally:
        net.close()


if __name__ == "__main__":
    main()
