"""A floor with as many Zenoh links as its node (issue 35): links counted and matched.

A process of a show split into a process per node links with every other one (a Zenoh
peer learns the others by gossip and dials them, and two peers that dialled each other keep
both links: each node here holds 15-18 link ends, the sim 25-27 with its control session's)
and keeps each alive: at sonibus's lease (1.5 s, a lost
robot noticed within 2 s) a keep-alive every 375 ms on each link that carries nothing else,
and the other end's read. That is the bus's cost of being a member, paid by any program on
it, minimal or not; a floor harness on a private pair of sessions (one or seven links) did
not pay it, and its node's ratio counted the difference as the node's (the gateway, which
receives nothing, 0.73 % of a core at a 1.5 s lease against 0.34 % at 10 s).

So ``Links`` runs a hub (a session that listens, outside every measurement) and starts each
floor's process through ``with_links``, which opens, when told, idle sessions to the hub in
that process: each one more link on the process's Zenoh runtime, whose threads send and read
its keep-alives as they do a node's. ``Links.match`` counts the link ends of each node and of
its floor (established TCP sockets, ``link_ends``, but a served HTTP port's) and tells each
floor how many to add.

>>> link_ends(os.getpid())
0
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from typing import Any

from common import free_port, zenoh_config
from floor import CONTEXT

IDLE = {"scouting/gossip/enabled": False, "listen/endpoints": []}
"""An idle link's session: it dials the hub only, and nobody dials it."""


def link_ends(pid: int, served: frozenset[int] = frozenset()) -> int:
    """The established TCP connections of process ``pid`` but those on a port in ``served``
    (its clients' WebSockets): its Zenoh links (two when both ends are in it)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:  # (closed meanwhile)
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    count = 0
    for table in ("tcp", "tcp6"):
        with open(f"/proc/{pid}/net/{table}") as rows:
            next(rows)
            for row in rows:
                fields = row.split()
                local, state, inode = fields[1], fields[3], fields[9]
                if state == "01" and inode in inodes and int(local.rpartition(":")[2], 16) not in served:
                    count += 1
    return count


def with_links(requests: Any, hub: str, target: Callable[..., None], *args: Any, **kwargs: Any) -> None:
    """Run ``target(*args, **kwargs)`` in this process, and beside it open, for each count read
    from ``requests``, that many idle sessions to ``hub``; closed when ``target`` returns."""
    import zenoh
    sessions: list[Any] = []

    def open_asked() -> None:
        while (count := requests.get()) is not None:
            sessions.extend(zenoh.open(zenoh_config(IDLE, connect=hub)) for _ in range(count))

    opener = threading.Thread(target=open_asked, daemon=True)
    opener.start()
    try:
        target(*args, **kwargs)
    finally:
        requests.put(None)
        opener.join(10)
        for session in sessions:
            session.close()


class Links:
    """The hub, and a request queue for each floor started through ``wrapped``."""

    def __init__(self) -> None:
        self.hub = f"tcp/127.0.0.1:{free_port()}"
        self.requests: dict[str, Any] = {}
        self._done = CONTEXT.Event()
        ready = CONTEXT.Event()
        self._process = CONTEXT.Process(target=_hub, args=(self.hub, ready, self._done), daemon=True)
        self._process.start()
        if not ready.wait(30):
            raise RuntimeError("the links' hub did not start")

    def wrapped(self, name: str, target: Callable[..., None], args: tuple[Any, ...]) -> dict[str, Any]:
        """``CONTEXT.Process``'s target and args for floor ``name``'s ``target(*args)``."""
        self.requests[name] = CONTEXT.Queue()
        return {"target": with_links, "args": (self.requests[name], self.hub, target, *args)}

    @staticmethod
    def process(links: Links | None, name: str, target: Callable[..., None], args: tuple[Any, ...],
                **kwargs: Any) -> Any:
        """Floor ``name``'s process (not started), through ``links`` when given (``wrapped``)."""
        run = links.wrapped(name, target, args) if links else {"target": target, "args": args}
        return CONTEXT.Process(**run, kwargs=kwargs, daemon=True)

    def match(self, floors: dict[str, int], nodes: dict[str, int], of: dict[str, str],
              served: frozenset[int] = frozenset(), timeout_s: float = 30.0) -> dict[str, dict[str, int]]:
        """Give each floor in ``floors`` (process ids by name) as many link ends as its node
        (``of[floor]``, in ``nodes``) has: ``{floor: {"node": n, "own": m}}``, its own before."""
        counted = {}
        for floor, pid in floors.items():
            node = of.get(floor)
            if node not in nodes or floor not in self.requests:
                continue
            counted[floor] = {"node": link_ends(nodes[node], served), "own": link_ends(pid, served)}
            if counted[floor]["node"] > counted[floor]["own"]:
                self.requests[floor].put(counted[floor]["node"] - counted[floor]["own"])
        deadline = time.monotonic() + timeout_s
        while any(link_ends(floors[floor], served) < want["node"] for floor, want in counted.items()):
            if time.monotonic() > deadline:
                raise RuntimeError(f"floors without their links: {counted}")
            time.sleep(0.1)
        return counted

    def close(self) -> None:
        self._done.set()
        self._process.join(10)
        if self._process.is_alive():
            self._process.kill()


def _hub(endpoint: str, ready: Any, done: Any) -> None:
    import zenoh
    session = zenoh.open(zenoh_config({"scouting/gossip/enabled": False}, listen=endpoint))
    ready.set()
    done.wait()
    session.close()
