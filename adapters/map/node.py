"""The ``map`` adapter: movement in, sound parameters out.

One worker takes the samples, frames and events its maps' sources name (``Streams``:
frames whole, joints picked out of them) and robots' infos (for the sources' ranges)
from one queue, feeds each map the values of its sources, and publishes each map's
output as a derived value of the node: ``<node>/derived/map/<map>``, described (unit,
range) on ``<node>/info/derived`` exactly as a features processor describes its
values, so every sink carries it as it carries those. A threshold's changes go out as
events on ``<node>/events/<map>``. A map none of whose sources sent for ``silent_s``
says so (log, stats, an event ``<node>/events/map``) instead of holding its last value
in silence; a source that never sent within ``unseen_s`` of the start is said once.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Iterable
from typing import Any

import zenoh

from sonibus.bus import codec, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.capped import PER_NAME, Capped
from sonibus.bus.errors import CommandError
from sonibus.bus.info import InfoRequests
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams

from . import ranges as spans
from .chain import Chain
from .config import MapConfig, MapSpec, Source
from .drive import Drive
from .edit import Editor
from .ranges import Ranges
from .steps import Calibration
from .targets import Target

log = logging.getLogger(__name__)

INFO = "\0info"      # queue items carrying a robot's info, so only the worker touches state
FEATURE = "map"      # <node>/derived/map/<map>
IMPULSE_S = 0.001    # an event's 1 falls back to 0 this much later (by the event's own clock)
INFO_RETRY_S = 0.5  # a robot's info asked again this often while a source waits for its range (features come late)
MAX_ROBOTS = 256     # robots whose ranges are kept (names from the bus)
MAX_KEYS = 10_000    # keys bound to map sources (patterns match names from the bus)
# a map, one of its sources, the component it takes (-1: the only one), and its range once known
Binding = tuple[Chain, Source, int, tuple[float, float] | None]


def _few(names: list[str], shown: int = 5) -> str:
    """``names`` joined, the first ``shown`` of them and how many more."""
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


class MapNode(Adapter):
    """Mappings from movement to sound: curves, smoothing, thresholds, out as signals with ranges and units."""

    Config = MapConfig
    counters = ("triggers", "waiting_info", "not_finite", "expr_errors", "clamped", "bad_source",
                "silent", "unseen", "capped", "requests", "requests_refused", *Drive.counters)

    def _start(self) -> None:
        cfg: MapConfig = self.config
        self.chains: dict[str, Chain] = {spec.name: Chain(spec, self.count) for spec in cfg.specs if spec.enabled}
        self._bindings: Capped[str, tuple[Binding, ...]] = Capped(MAX_KEYS, 4 << 20)
        self._ranges: dict[str, Ranges] = {}
        self._matchers = [(zenoh.KeyExpr(keys.expr(source.pattern)), chain, source)
                          for chain in self.chains.values() for source in chain.spec.sources]
        self._heard: dict[str, float] = {}         # map → when a source last sent (monotonic)
        self._seen: set[Source] = set()            # sources that sent at least once
        self._silent: dict[str, float] = {}        # map → when it went silent (monotonic)
        self._back: list[str] = []                 # maps silent until this message
        self._started = time.monotonic()
        self._unseen_said = False
        self._seq = 0
        self._publishers = {name: self.own(self.bus.stream_publisher(self.output_key(name))) for name in self.chains}
        self._maps_lock = threading.Lock()  # the maps as they run: the worker's, and an edit's that replaces one
        self._inputs: dict[str, float] = {}        # map → its curve's last input (0..1), for views
        self._learning: dict[tuple[str, str], Calibration] = {}  # (map, source) → a learn under way
        self._subscribed = [zenoh.KeyExpr(keys.expr(p)) for p in cfg.patterns]
        self._reply = codec.encode(self.described())
        where = keys.derived_info(self.name)
        self.own(self.bus.serve(where, lambda query: query.reply(where, self._reply, encoding=codec.ENCODING)))
        self.editor = Editor(self, cfg.maps, self.file)
        self.own(self.bus.serve(keys.maps(self.name), self.editor.serve))
        self._queue = self.own(SampleQueue(cfg.queue))
        self._info = InfoRequests(self.bus, lambda robot, info: self._queue.put((INFO, (robot, info))),
                                  lambda robot, text: self.warn("info", text), INFO_RETRY_S)
        self._streams = self.own(Streams(self.bus, cfg.patterns, self._queue, per_joint_keys=cfg.per_joint_keys))
        targets = {name: chain.spec.target for name, chain in self.chains.items() if chain.spec.target}
        self._drive = Drive(self, targets) if targets else None  # (maps that drive robots: drive.py)
        self._drive_lock = threading.Lock()  # (a Drive made when a map added live is the first with a target)
        for robot in {s.pattern.split("/")[0] for spec in cfg.specs for s in spec.sources} | {
                t.robot for t in targets.values()}:
            if keys.is_concrete(robot):
                self._info.ask(robot)  # (before its first sample: the first values are mapped, not waited for)
        self.spawn(self._run, "map")

    def output_key(self, name: str) -> str:
        """Where map ``name``'s output goes: ``<node>/derived/map/<name>``."""
        return keys.derived(self.name, FEATURE, name)

    def described(self) -> dict[str, Any]:
        """The ``<node>/info/derived`` reply: each map's output with its unit and range, and its events."""
        specs = [chain.spec for chain in self.chains.values()]
        return {"robot": self.name, "alone": True, "processor": {"host": self.bus.host, "node": self.name},
                "derived": [{"name": f"{FEATURE}/{s.name}", "key": self.output_key(s.name), "unit": s.unit, "size": 1,
                             "min": s.low, "max": s.high, "sources": [src.pattern + (f".{src.axis}" if src.axis
                                                                                     else "") for src in s.sources]}
                            for s in specs],
                "events": {s.name: {"key": keys.event(self.name, s.name), "on": s.threshold[0],
                                    "off": s.threshold[1]} for s in specs if s.threshold}}

    # -- live edits (``edit.py``) ------------------------------------------------------------

    def replace(self, spec: MapSpec) -> None:
        """Run ``spec`` in place of its map (or as a new one) from the next value on (its state
        starts anew; what it drives, its ``target``, too); ``CommandError`` for a source the
        node does not listen to (a restart would)."""
        for src in spec.sources:
            if spec.enabled and not any(p.includes(zenoh.KeyExpr(keys.expr(src.pattern))) for p in self._subscribed):
                raise CommandError("bad_request", f"map '{spec.name}': source '{src.pattern}' is not among those "
                                                  "this node listens to — save, then restart the run")
        publisher = None
        if spec.enabled and spec.name not in self._publishers:
            publisher = self.own(self.bus.stream_publisher(self.output_key(spec.name)))
        with self._maps_lock:
            if publisher is not None:
                self._publishers[spec.name] = publisher
            if spec.enabled:
                self.chains[spec.name] = Chain(spec, self.count)
            else:
                self.chains.pop(spec.name, None)
                self._silent.pop(spec.name, None)
            self._inputs.pop(spec.name, None)
            self._learning = {k: v for k, v in self._learning.items() if k[0] != spec.name or spec.enabled}
            self._matchers = [(zenoh.KeyExpr(keys.expr(source.pattern)), chain, source)
                              for chain in self.chains.values() for source in chain.spec.sources]
            self._bindings.clear()
            self._reply = codec.encode(self.described())
        self._set_target(spec.name, spec.target if spec.enabled else None)

    def remove(self, name: str) -> None:
        """Stop running map ``name``: its output and what it drives (an edit that disables it, and
        ``list`` no more; the editor keeps its table for undo)."""
        with self._maps_lock:
            self.chains.pop(name, None)
            self._silent.pop(name, None)
            self._inputs.pop(name, None)
            self._heard.pop(name, None)
            self._learning = {k: v for k, v in self._learning.items() if k[0] != name}
            self._matchers = [(zenoh.KeyExpr(keys.expr(source.pattern)), chain, source)
                              for chain in self.chains.values() for source in chain.spec.sources]
            self._bindings.clear()
            self._reply = codec.encode(self.described())
        self._set_target(name, None)

    def _set_target(self, name: str, target: Target | None) -> None:
        """Map ``name`` drives ``target`` (None: nothing) from now on: the drive's caps, and its
        halts (a robot stopped stays halted until resumed, for a map added after the stop too)."""
        with self._drive_lock:
            if self._drive is None:
                if target is None:
                    return
                self._drive = Drive(self, {})
            self._drive.set_target(name, target)
        if target is not None and keys.is_concrete(target.robot):
            self._info.ask(target.robot)  # (its joints' limits: a map past them is said)

    def start_learning(self, name: str, source: str, seconds: float) -> None:
        """Learn ``source``'s range over its next ``seconds`` of values (``Editor.learned`` then)."""
        with self._maps_lock:
            self._learning[(name, source)] = Calibration(seconds)

    def live(self, name: str) -> dict[str, Any]:
        """Map ``name``'s live state: its last input and output, silent, what it learns."""
        with self._maps_lock:
            chain = self.chains.get(name)
            learning = [{"source": s, "seconds": c.seconds, "range": c.range}
                        for (n, s), c in self._learning.items() if n == name]
            return {"input": self._inputs.get(name), "output": chain.value if chain else None,
                    "silent": name in self._silent, "learning": learning[0] if learning else None}

    def halted(self) -> dict[str, float]:
        """The robots a stop halted the maps of, until resumed (wall-clock time of the stop)."""
        return self._drive.status()["halted"] if self._drive is not None else {}

    def metrics(self) -> dict[str, Any]:
        """Each map's last output, and the maps silent now (seconds since their last source value)."""
        now = time.monotonic()
        return {"outputs": {n: c.value for n, c in list(self.chains.items()) if c.value is not None},
                "silent_maps": {n: round(now - self._heard.get(n, self._started), 1) for n in list(self._silent)},
                **(self._drive.metrics() if getattr(self, "_drive", None) is not None else {})}

    # -- the loop ---------------------------------------------------------------------

    def _run(self) -> None:
        wait = 0.2
        while not self.stopping.is_set():
            for key, payload in self._queue.drain(timeout=wait):
                if key == INFO:
                    self._learn(*payload)
                    continue
                message = self._streams.take(key, payload, self.count, self.warn)
                if message is not None:
                    with self._maps_lock:
                        self._take(message)
                        learned = self._learned()
                    for name, source, span in learned:  # (outside the lock: the edit replaces the map)
                        self.editor.learned(name, source, span)
            wait = min(0.2, self._drive.flush()) if self._drive is not None else 0.2
            with self._maps_lock:
                self._watch(time.monotonic())

    def _take(self, message: Incoming) -> None:
        if message.event is not None:  # an event is an impulse: 1, then 0 again (a threshold: on, then off)
            t = float(message.event.get("t") or time.time())
            self._map([(message.source, (1.0,))], t)
            self._map([(message.source, (0.0,))], t + IMPULSE_S)
            return
        if message.parts is not None:  # a derived frame: its values, each as its key's sample
            self._map([(part.source, part.values) for part in message.parts], message.t)
            return
        self._map([(message.source, message.values)] if message.selected is None else
                  zip(message.selected.sources, ((v,) for v in message.values), strict=True), message.t)

    def _map(self, values: Iterable[tuple[keys.Key, tuple[float, ...]]], t: float) -> None:
        """Feed each map the values of its sources among ``values`` (all of time ``t``), then
        compute and publish the maps they fed."""
        touched: dict[str, Chain] = {}
        now = time.monotonic()
        for source, numbers in values:
            for chain, src, component, known in self._bound(source):
                span = known or self._span(chain, src, source, component)
                if len(numbers) > 1 and component < 0:
                    self.count("bad_source")
                    axes = self._ranges.get(source.robot)
                    named = ", ".join(axes.axes.get(source.key, ())) if axes else ""
                    self.warn("source", f"map '{chain.spec.name}': '{source.key}' has {len(numbers)} values"
                                        f"{f' ({named})' if named else ''}: name one, as {source.key}."
                                        f"{(named.split(', ')[0] if named else '0')}")
                    continue
                if component >= len(numbers):
                    self.count("bad_source")
                    self.warn("source", f"map '{chain.spec.name}': '{source.key}' has no component "
                                        f"'{src.axis}' (it has {len(numbers)} values)")
                    continue
                name = chain.spec.name
                self._heard[name] = now
                self._seen.add(src)
                if self._learning and (name, src.name) in self._learning:
                    self._learning[(name, src.name)](t, numbers[max(component, 0)])
                if chain.feed(src.name, numbers[max(component, 0)], span, t):
                    touched[name] = chain
        sent = sum(self._publish(name, chain, t) for name, chain in touched.items())
        if self._back:
            many = len(self._back) > 1
            log.info("%s: map%s %s: %s sources send again", self.name, "s" if many else "",
                     _few([f"'{n}'" for n in self._back]), "their" if many else "its")
            self._back.clear()
        if sent:
            self.count("sent", sent)
            self.record_latency(time.time() - t)  # (once a message, however many maps it fed)

    def _publish(self, name: str, chain: Chain, t: float) -> bool:
        """Compute map ``name`` and publish its output (True) and its threshold's change."""
        out = chain.compute(t)
        if out is not None:
            self._inputs[name] = out.fraction
        for source, span in chain.frozen:
            log.info("%s: map '%s': source '%s' calibrated to [%g, %g]", self.name, name, source, *span)
        chain.frozen.clear()
        if out is None:
            return False
        if self._drive is not None and chain.spec.target is not None:
            self._drive.take(name, out.value, out.trigger)
        if name in self._silent:
            del self._silent[name]
            self._back.append(name)
        self._seq += 1
        if out.trigger is not None:
            self.bus.put(keys.event(self.name, name), {"t": t, "kind": name, "state": out.trigger,
                                                       "value": chain.value if chain.value is not None else 0.0})
            self.count("triggers")
        if out.value is None:
            return False
        self._publishers[name].put(codec.encode({"t": t, "seq": self._seq, "v": out.value}))
        return True

    def _learned(self) -> list[tuple[str, str, tuple[float, float]]]:
        """The learns that froze (taken off the list)."""
        if not self._learning:
            return []
        done = [(name, source, c.range) for (name, source), c in self._learning.items() if c.frozen]
        for name, source, _ in done:
            del self._learning[(name, source)]
        return done  # type: ignore[return-value]

    def _bound(self, source: keys.Key) -> tuple[Binding, ...]:
        """The maps' sources that ``source`` feeds, with its range when known (worked out once per
        key, and again when a robot's info comes)."""
        found = self._bindings.get(source.key)
        if found is None:
            ranges = self._ranges.get(source.robot)
            found = tuple((chain, src, component, (0.0, 1.0) if source.section == "events" else
                           ranges.of(source, component) if ranges is not None else None)
                          for expr, chain, src in self._matchers if expr.intersects(source.key)
                          for component in (self._component(src, source),))
            self._bindings.put(source.key, found, 2 * len(source.key) + PER_NAME)
        return found

    def _component(self, src: Source, source: keys.Key) -> int:
        """Which component of ``source``'s values ``src`` takes (see ``ranges.component``)."""
        ranges = self._ranges.get(source.robot)
        return spans.component(src.axis, ranges.axes.get(source.key, ()) if ranges is not None else ())

    def _span(self, chain: Chain, src: Source, source: keys.Key, component: int) -> tuple[float, float] | None:
        """The range of ``source``'s values from its robot's info (events: 0..1); None if not
        known yet (its info is asked for, unless the map does not need it)."""
        if source.section == "events":
            return (0.0, 1.0)
        ranges = self._ranges.get(source.robot)
        span = ranges.of(source, component) if ranges is not None else None
        if span is None and src.name not in chain.spec.ranges and not chain.spec.calibrate_s:
            self.count("waiting_info")
            self._info.ask(source.robot)
            if ranges is not None and time.monotonic() - self._started > self.config.unseen_s:  # (not at start:
                # a features node describes a robot after its first frames, a moment after the owner's info)
                self.warn("range", f"map '{chain.spec.name}': no range yet for '{source.key}' in {source.robot}'s "
                                   "info (a derived value's comes from the features node): its values wait; "
                                   "or give the map one: from = [LOW, HIGH]")
        return span

    def _learn(self, robot: str, info: dict[str, Any]) -> None:
        if robot not in self._ranges and len(self._ranges) >= MAX_ROBOTS:
            self.capped(f"robot '{robot}': its ranges not kept, already {MAX_ROBOTS} robots'")
            return
        self._ranges[robot] = Ranges(info)
        self._bindings.clear()  # (components by axis name are worked out again with this info)
        if self._drive is not None:
            self._drive.learned(robot, self._ranges[robot].joints)

    # -- silence ----------------------------------------------------------------------

    def _watch(self, now: float) -> None:
        cfg: MapConfig = self.config
        if not self._unseen_said and now - self._started >= cfg.unseen_s:
            self._unseen_said = True
            for chain in self.chains.values():
                for src in chain.spec.sources:
                    if src not in self._seen:
                        self.count("unseen")
                        log.warning("%s: map '%s': source '%s' sent nothing in %g s — is it published? "
                                    "(sonibus echo '%s'%s)", self.name, chain.spec.name, src.pattern, cfg.unseen_s,
                                    src.pattern, "; a derived value needs the features node"
                                    if src.section == "derived" else "")
        gone = [name for name in self.chains if name not in self._silent
                and now - self._heard.get(name, math.inf) >= cfg.silent_s]
        for name in gone:
            self._silent[name] = now
            self.count("silent")
            self.bus.put(keys.event(self.name, "map"), {"t": time.time(), "kind": "map", "map": name,
                                                        "state": "silent"})
        if len(gone) == 1:
            chain = self.chains[gone[0]]
            last = f"{chain.value:g} {chain.spec.unit}".rstrip() if chain.value is not None else "none"
            log.warning("%s: map '%s': its sources (%s) silent for %g s; its output stops at its last value (%s)",
                        self.name, gone[0], ", ".join(s.pattern for s in chain.spec.sources), cfg.silent_s, last)
        elif gone:  # (a robot that stops silences every map of its joints at once: one line, not fifty)
            sources = dict.fromkeys(s.pattern for name in gone for s in self.chains[name].spec.sources)
            log.warning("%s: %d maps (%s) silent for %g s, their sources (%s) with them; their outputs stop at "
                        "their last values", self.name, len(gone), _few(gone), cfg.silent_s, _few(list(sources)))
