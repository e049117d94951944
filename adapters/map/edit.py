"""Editing a map node's maps while they run: requests on ``<node>/maps/<verb>``, served and
answered like a robot's commands (the gate, the verb's schema in ``schemas/v1/maps/``,
then ``{"ok": true, "result": ...}`` or ``{"ok": false, "error": {"code", "message"}}``).

    list                              every map: its table, live input and output, curve
    edit  {map, set: {...}, unset: [...]}   steps of one map changed, as in the file
    learn {map, seconds?, source?}    the next N seconds of a source set its `from`
    undo  {map?}                      the last change taken back (an add's: the map removed)
    add   {map, table}                a new map, its table as in the file
    remove {map}                      a map taken out (its output, what it drives)
    save                              the maps as they run, written into the file

An edit is checked exactly as the installation file is (``parse_map``): refused with the
reason in one line and the running map untouched, or applied before the reply, so the
next value a source sends goes through the new map. Every change (an edit, a learned
range, an undo's own) is kept for undo, the last ``MAX_UNDO``.
"""

from __future__ import annotations

import copy
import logging
import threading
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zenoh

from sonibus import schemas
from sonibus.bus import keys, messages
from sonibus.bus.commands import serving
from sonibus.bus.errors import CommandError, ConfigError

from .config import MAX_MAPS, MapSpec, parse_map
from .save import SaveError, save

if TYPE_CHECKING:
    from .node import MapNode

log = logging.getLogger(__name__)

MAX_UNDO = 64           # changes kept for undo, all maps together
CURVE_SAMPLES = 33      # points of a curve as ``list`` gives it, for drawing
LEARN_S = 5.0           # a learn's seconds when the request gives none


class Editor:
    """The maps' tables as they run now, their history, and the requests that change them."""

    def __init__(self, node: MapNode, tables: dict[str, dict[str, Any]], path: Path | None) -> None:
        self.node = node
        self.path = path                   # the installation file ("save"), None when not built from one
        self.tables = copy.deepcopy(tables)
        self.specs = {name: parse_map(name, table) for name, table in self.tables.items()}  # (checked at load)
        # (map, its table before; None: it was not there, an add's)
        self.history: deque[tuple[str, dict[str, Any] | None]] = deque(maxlen=MAX_UNDO)
        self.removed: set[str] = set()     # maps removed live: save takes them out of the file
        self._lock = threading.Lock()      # (queries come on several Zenoh threads; learns end on the worker)
        self._gate = messages.Gate(node.bus.limits)

    # -- the queryable -------------------------------------------------------------------

    def serve(self, query: zenoh.Query) -> None:
        """Answer one request on ``<node>/maps/<verb>``."""
        verb = str(query.key_expr).split("/", 2)[2]  # (the query's key: `*/maps/list` asks every map node)
        self.node.count("requests")
        serving.answer(query, verb, lambda: self.answer(verb, self._args(verb, query)),
                       lambda: self.node.count("requests_refused"), keys.maps(self.node.name, verb))

    def _args(self, verb: str, query: zenoh.Query) -> dict[str, Any]:
        if verb not in schemas.request_verbs("maps"):
            raise CommandError("unknown_verb", f"unknown request '{verb}' — a map node takes "
                                               f"{', '.join(schemas.request_verbs('maps'))}")
        return serving.arguments(self._gate, query, verb, lambda: self.node.count("bad"), section="maps")

    def answer(self, verb: str, args: dict[str, Any]) -> dict[str, Any]:
        """The result of a checked request (``CommandError`` when refused)."""
        if verb == "list":
            return {"node": self.node.name, "file": str(self.path or ""), "maps": self.listed(),
                    "halted": self.node.halted()}
        if verb == "edit":
            return self.edit(args["map"], args.get("set", {}), args.get("unset", []))
        if verb == "learn":
            return self.learn(args["map"], float(args.get("seconds", LEARN_S)), args.get("source"))
        if verb == "undo":
            return self.undo(args.get("map"))
        if verb == "add":
            return self.add(args["map"], args["table"])
        if verb == "remove":
            return self.remove(args["map"])
        return self.save()

    # -- the verbs -----------------------------------------------------------------------

    def edit(self, name: str, given: dict[str, Any], unset: Sequence[str] = ()) -> dict[str, Any]:
        """Set ``given`` steps of map ``name`` and remove ``unset`` ones; applied, or refused
        with the reason (the running map unchanged)."""
        with self._lock:
            before = self._table(name)
            table = {**{k: v for k, v in before.items() if k not in unset}, **given}
            if "points" in given and "curve" not in given and "curve" in table:
                table["curve"] = "points"   # (breakpoints given: the curve they draw)
            elif table.get("curve", "points" if "points" in table else "linear") != "points":
                table.pop("points", None)   # (a curve changed from breakpoints drops them)
            if table.get("curve") not in ("exp", "log") and "base" not in given:
                table.pop("base", None)
            self._apply(name, table)
            self.history.append((name, before))
        changed = sorted(k for k in {*before, *table} if before.get(k) != table.get(k))
        log.info("%s: map '%s' edited: %s", self.node.name, name, ", ".join(changed) or "nothing changed")
        return {"map": name, "table": table, "changed": changed}

    def undo(self, name: str | None = None) -> dict[str, Any]:
        """Take back the last change (of map ``name`` when given)."""
        with self._lock:
            at = next((i for i in range(len(self.history) - 1, -1, -1)
                       if name is None or self.history[i][0] == name), None)
            if at is None:
                raise CommandError("bad_request", f"undo: nothing to undo{f' for map {name!r}' if name else ''} "
                                                  f"(the last {MAX_UNDO} changes are kept)")
            which, table = self.history[at]
            if table is not None and which not in self.tables and len(self.tables) >= MAX_MAPS:
                raise CommandError("bad_request", f"undo: taking back the removal of {which!r} would run more than "
                                                  f"{MAX_MAPS} maps in one node — remove one first")
            if table is None:
                self._take_out(which)
            else:
                self._apply(which, table)
            del self.history[at]
        log.info("%s: map '%s': last %s undone", self.node.name, which, "add" if table is None else "change")
        return {"map": which, "table": table, "undone": True}

    def add(self, name: str, table: dict[str, Any]) -> dict[str, Any]:
        """Run a new map ``name`` of ``table`` (as in the file), checked as the file is; refused
        with the reason, the other maps running on."""
        with self._lock:
            if name in self.tables:
                raise CommandError("bad_request", f"add: node '{self.node.name}' already has a map {name!r} — "
                                                  "edit it, or remove it first")
            if len(self.tables) >= MAX_MAPS:
                raise CommandError("bad_request", f"add: node '{self.node.name}' runs {len(self.tables)} maps, at "
                                                  f"most {MAX_MAPS} in one node — remove one, or add a node")
            self._apply(name, copy.deepcopy(table))
            self.history.append((name, None))
        log.info("%s: map '%s' added", self.node.name, name)
        return {"map": name, "table": self.tables[name], "added": True}

    def remove(self, name: str) -> dict[str, Any]:
        """Take map ``name`` out: its output stops, what it drives is sent no more (undo adds it back)."""
        with self._lock:
            table = self._table(name)
            self._take_out(name)
            self.history.append((name, table))
        log.info("%s: map '%s' removed", self.node.name, name)
        return {"map": name, "removed": True}

    def learn(self, name: str, seconds: float, source: str | None = None) -> dict[str, Any]:
        """Start learning a source's range (its first by default) from its next ``seconds`` of values."""
        with self._lock:
            self._table(name)
            spec = self.specs[name]
        names = [s.name for s in spec.sources]
        source = source or names[0]
        if source not in names:
            raise CommandError("bad_request", f"learn: map '{name}' has no source '{source}' — sources: "
                                              f"{', '.join(names)}")
        if not spec.enabled:
            raise CommandError("bad_request", f"learn: map '{name}' is disabled — enable it first")
        self.node.start_learning(name, source, seconds)
        log.info("%s: map '%s': learning the range of source '%s' for %g s", self.node.name, name, source, seconds)
        return {"map": name, "source": source, "seconds": seconds}

    def learned(self, name: str, source: str, span: tuple[float, float]) -> None:
        """A learn ended (called by the node's worker): the range becomes the map's ``from``, an
        edit like any other (undo takes it back)."""
        with self._lock:
            table, spec = self.tables.get(name), self.specs.get(name)
        if table is None or spec is None:
            return
        ranges = table.get("from")
        single = len(spec.sources) == 1
        value: Any = [span[0], span[1]] if single else {**(ranges if isinstance(ranges, dict) else {}),
                                                        source: [span[0], span[1]]}
        try:
            self.edit(name, {"from": value})
        except CommandError as exc:
            self.node.warn("learn", f"map '{name}': the range learned for '{source}' not taken: {exc.message}")
            return
        log.info("%s: map '%s': source '%s' learned: from = [%g, %g]", self.node.name, name, source, *span)

    def save(self) -> dict[str, Any]:
        """Write the maps as they run into the installation file."""
        if self.path is None:
            raise CommandError("bad_request", "save: this node was not started from an installation file — "
                                              "nothing to write into")
        with self._lock:
            tables, removed = copy.deepcopy(self.tables), set(self.removed)
        try:
            save(self.path, self.node.name, tables, removed)
        except SaveError as exc:
            raise CommandError("internal", f"save: {self.path}: {exc}") from None
        log.info("%s: maps saved into %s", self.node.name, self.path)
        return {"file": str(self.path), "maps": sorted(tables)}

    def listed(self) -> list[dict[str, Any]]:
        """Every map as ``list`` gives it: its table, whether it runs, its live values, its curve."""
        with self._lock:
            tables, specs = copy.deepcopy(self.tables), dict(self.specs)
        out = []
        for name, table in tables.items():
            spec = specs[name]
            out.append({"name": name, "table": table, "enabled": spec.enabled, "unit": spec.unit,
                        "to": list(spec.to), "sources": [s.name for s in spec.sources],
                        "curve": [[x, spec.curve(x)] for x in (i / (CURVE_SAMPLES - 1) for i in range(CURVE_SAMPLES))],
                        **self.node.live(name)})
        return out

    # -- shared --------------------------------------------------------------------------

    def _table(self, name: str) -> dict[str, Any]:
        table = self.tables.get(name)
        if table is None:
            raise CommandError("bad_request", f"no map {name!r} in node '{self.node.name}' — maps: "
                                              f"{', '.join(self.tables)}")
        return table

    def _apply(self, name: str, table: dict[str, Any]) -> MapSpec:
        """Check ``table`` as the file is, then run it (under ``_lock``)."""
        try:
            spec = parse_map(name, table)
        except ConfigError as exc:
            raise CommandError("bad_request", f"map '{name}': {exc}") from None
        self.node.replace(spec)
        self.tables[name], self.specs[name] = table, spec
        self.removed.discard(name)
        return spec

    def _take_out(self, name: str) -> None:
        """Stop map ``name`` and forget its table (under ``_lock``)."""
        self.node.remove(name)
        del self.tables[name], self.specs[name]
        self.removed.add(name)
