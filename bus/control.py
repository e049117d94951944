"""The control session: ``stop`` served and sent where data cannot hold it up.

A process's data session takes each link's messages in order on one Zenoh
thread: when a subscription's callback channel (zenoh-python's, 256 samples) is
full, that thread waits for Python, and a ``stop`` that came over the same link
waits behind the flood (0.3-0.9 s after 2,000 frames at 5,000/s, issue 33).
So every process that owns robots (and ``sonibus top``) opens one more session, the
control session, with the data session's config (mode, namespace, login, TLS,
access control) but links of its own. It listens nowhere and dials: where the data
session connects (the data session itself when that is a plain listener), then, told
by Zenoh's gossip, every other process's data session. Nobody dials it, so no data
session routes through it (a listening control session, linked by gossip with every
data session, cost a sink its frames across two machines: tests/net/test_multihost.py).
An asker's ``stop`` leaves from it at Zenoh's real-time priority, express, on a link
that carries no data and that the owner's data session reads on a Zenoh task of its
own; a stop from a process without one (``sonibus send``) reaches the owner's control
session over the link it dialled, where ``<robot>/cmd/stop`` is served by a callback
called on Zenoh's own thread (no channel, no Python thread in between).

>>> from contextlib import closing
>>> from sonibus.bus.busconfig import BusConfig
>>> from sonibus.bus.session import open_session
>>> cfg = BusConfig(multicast=False, listen=("tcp/127.0.0.1:0",))
>>> with closing(open_session(cfg)) as data, closing(open_control(cfg, data)) as control:
...     str(control.zid()) != str(data.zid())
True
"""

from __future__ import annotations

from dataclasses import replace

import zenoh

from .busconfig import BusConfig
from .session import CONTROLS, from_here, listening, open_session

URGENT = {"priority": zenoh.Priority.REAL_TIME, "express": True}
"""Zenoh options of a stop: ahead of every data message in Zenoh's queues."""
URGENT_REPLY = {"express": True}
"""Of its reply (which travels at its query's priority: Zenoh ignores a reply's own)."""


def control_config(config: BusConfig, data: zenoh.Session) -> BusConfig:
    """``config`` as the control session of ``data`` opens it (see the module's docstring)."""
    if config.mode == "client":  # (its router links it with everybody: no listen of its own)
        return config
    here: tuple[str, ...] = ()
    if not config.connect and not config.multicast:  # (the others come to the data session: so does this one)
        here = tuple(from_here(endpoint) for endpoint in listening(data) if not endpoint.endswith(":0"))
    # no listen: it dials the others (gossip tells it whom), nobody dials it, so no data session
    # links with it nor routes through it
    return replace(config, mode="peer", listen=(), connect=tuple(dict.fromkeys((*config.connect, *here))),
                   options={**config.options, "listen/endpoints": []})


def open_control(config: BusConfig, data: zenoh.Session) -> zenoh.Session:
    """The control session of the process whose data session is ``data``; its opener closes it."""
    session = open_session(control_config(config, data))
    CONTROLS.add(str(session.zid()))
    return session
