"""The operator page's mappings panel, on the server's side: every map node's maps, asked
(``*/maps/list``) ``MAPS_EVERY_S`` while an operator's page is open and a map node is
listed, and the page's edits carried to the node that runs the map (``<node>/maps/<verb>``),
its answer the page's reply.

Whether a map node is on the bus is read from the nodes' stats the web node lists anyway
(their ``adapter``, ``map``; once a second): with none the panel asks nothing and wakes
for nothing, where it asked every ``NO_MAPS_EVERY_S`` (a Zenoh query a second with a page
open: ~0.1 % of a core; issue 35). Zenoh's matching status of a querier does not serve
here: it matches the queryables whose key holds the querier's, and ``*/maps/list`` is
held by none (a map node serves ``<node>/maps/**``).

Two messages go to the pages: ``maps`` (each node's maps: tables, curves; sent when they
change, and to a page that connects) and ``map_values`` (each map's live input, output,
silence and learn, at every look).
"""

from __future__ import annotations

import functools
import json
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from sonibus.bus import client as bus_client
from sonibus.bus import keys, messages
from sonibus.bus.errors import CommandError

from . import protocol
from .protocol import RESUME

if TYPE_CHECKING:
    from sonibus.bus.adapter import Adapter

    from .server import Client, Pages

MAPS_EVERY_S = 0.2     # how often the maps' live values are asked while a page is open
NO_MAPS_EVERY_S = 1.0  # and how often while a map node is listed but the last look found none
ASK_TIMEOUT_S = 1.0    # how long a look waits for the map nodes' answers
MAX_MAP_NODES = 16     # map nodes shown (names from the bus)
MAX_MAPS_BYTES = 4 << 20  # a look's maps, as JSON: past this the nodes past it are left out (said, counted)
LIVE = ("input", "output", "silent", "learning")  # what changes at every look
_dumps = functools.partial(json.dumps, allow_nan=False)


class MapsPanel:
    """Looks at the map nodes for ``pages`` (``run`` on a worker of ``adapter``)."""

    def __init__(self, adapter: Adapter, pages: Pages, listed: Callable[[], bool]) -> None:
        """``listed``: whether a map node is among the nodes listed now (their stats)."""
        self.adapter, self.pages, self._listed = adapter, pages, listed
        self._structure = ""  # the last ``maps`` message sent
        self._found = False   # whether the last look found a map node
        self._wanted = threading.Event()  # an operator's page came, a map node listed, or the node stops
        pages.on_operator.append(self._wanted.set)

    def nodes_listed(self) -> None:
        """The nodes' list was made anew (their stats, once a second): a look if a map node is in it."""
        if not self._found and self._listed():
            self._wanted.set()

    def run(self) -> None:
        """Look every ``MAPS_EVERY_S`` while an operator's page is open and a map node is listed
        (``NO_MAPS_EVERY_S`` while the last look found none to show; one look more when the
        last goes, to clear the panel); else wait for both (not a wake-up a look for nobody)."""
        stopping = self.adapter.stopping
        self.adapter.when_stopping(self._wanted.set)

        def wanted() -> bool:
            return bool(self.pages.operators) and (self._found or self._listed())
        while not stopping.is_set():
            if not wanted():
                self._wanted.clear()
                if not wanted():  # (what came between: set after the clear, or seen here)
                    self._wanted.wait()
                continue
            if stopping.wait(MAPS_EVERY_S if self._found else NO_MAPS_EVERY_S):
                return
            if self.pages.operators:
                self.look()

    def look(self) -> None:
        """Ask every map node for its maps; tell the pages what changed."""
        answers = self.adapter.bus.query(keys.maps("*", "list"), {}, timeout=ASK_TIMEOUT_S)
        nodes, size = [], 0
        for answer in sorted((a["result"] for a in answers if a.get("ok") and isinstance(a.get("result"), dict)),
                             key=lambda r: str(r.get("node"))):
            try:
                messages.json_like(answer, "maps")
                text = _dumps(answer)
            except (messages.BadMessage, ValueError, TypeError) as exc:
                self.adapter.warn("maps", f"map node {str(answer.get('node'))[:64]!r}: its maps cannot be shown: {exc}")
                continue
            size += len(text)
            if len(nodes) >= MAX_MAP_NODES or size > MAX_MAPS_BYTES:
                self.adapter.capped(f"map node {str(answer.get('node'))[:64]!r} not shown: already {len(nodes)} "
                                    f"nodes' maps on the page (at most {MAX_MAP_NODES}, {MAX_MAPS_BYTES >> 20} MiB)")
                break
            nodes.append(answer)
        structure = _dumps({"type": "maps", "nodes": [
            {"node": n.get("node"), "file": n.get("file"),
             "maps": [{k: v for k, v in m.items() if k not in LIVE} for m in n.get("maps", ())]} for n in nodes]})
        if structure != self._structure:
            self._structure = structure
            self.pages.maps(structure)
        self._found = bool(nodes)
        if not nodes:  # (no map node: nothing live to show, 5 messages a second to each page for nothing)
            return
        self.pages.to_operators(_dumps({"type": "map_values", "t": time.time(), "nodes": {
            n.get("node"): {m.get("name"): {k: m.get(k) for k in LIVE} for m in n.get("maps", ())} for n in nodes},
            "halted": {n.get("node"): _halted(n.get("halted")) for n in nodes}}))


def _halted(given: object) -> list[str]:
    """The robots a node's ``list`` says a stop halted (names from the bus: at most 64, each shortened)."""
    return sorted(str(robot)[:64] for robot in given)[:64] if isinstance(given, dict) else []


def forward(adapter: Adapter, pages: Pages, client: Client, request: protocol.MapRequest, timeout: float) -> None:
    """Carry a page's ``map`` request to its node; the node's answer (or why none came) is the reply."""
    adapter.count("commands")
    client.asking += 1  # (bounded by the server, as a page's commands are: MAX_ASKING)
    # resume is what `sonibus resume` asks: the node's <node>/program/resume, not one of its maps/ verbs
    key = keys.program(request.node, "resume") if request.verb == RESUME else keys.maps(request.node, request.verb)
    nobody = CommandError("not_found", f"{request.verb}: no map node '{request.node}' on the bus ({key} is served "
                                       "by nothing)")

    def answered(outcome: bus_client.Outcome) -> None:
        client.asking -= 1
        client.answer(protocol.reply(request.id, outcome))
    bus_client.ask_key(adapter.bus, key, request.args, lambda outcome: pages.web.call(answered, outcome), timeout,
                       nobody, f"map node '{request.node}'")
