"""OSC sink: bus samples and events → OSC over UDP, per target as configured."""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from sonibus.bus import lateness, presence
from sonibus.bus.adapter import Adapter
from sonibus.bus.capped import Capped, size_of
from sonibus.bus.errors import ConfigError
from sonibus.bus.frames import Frame, FrameAssembler
from sonibus.bus.info import InfoRequests
from sonibus.bus.keys import Key
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Parts, Selected, Streams

from . import scale
from .config import OscSinkConfig, parse_target
from .encode import EncodeError
from .link import MAX_PLAN_BYTES, MAX_PLANS, Link, Plan
from .profiles import Rendered, shape_of
from .ranges import MAX_ROBOTS, RobotRanges

log = logging.getLogger(__name__)

INFO_RETRY_S = 2.0
HEARD_EVERY_S = 0.5       # how often a robot's data is told to presence (its silence is warned of after 3 s)
LISTENING_AFTER_S = 2.0   # a target whose host has not refused a datagram for this long: something listens there
DIRECT_WAIT_S = 0.002     # a frame waits this long at most on Zenoh's thread for another one taken there
_REFUSED = (struct.error, OverflowError, ValueError)  # what packing a value OSC cannot carry raises
_NOT_PLANNED = (*_REFUSED, TypeError)  # and a derived value of another shape than its plan's (a number for a list)
_NEVER = -math.inf
_FOREVER = math.inf


class OscSink(Adapter):
    """Forwards joints, derived values and events to OSC receivers (Pd, Max, SuperCollider) over UDP."""

    Config = OscSinkConfig
    counters = ("unencodable", "late", "waiting_info", "send_errors", "unreachable", "skipped")

    def _start(self) -> None:
        cfg: OscSinkConfig = self.config
        self._ranges = RobotRanges()
        self._heard: dict[str, float] = {}  # robot → when its data was last told to presence
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: self.warn("info", text),
                                  INFO_RETRY_S, derived_alone=True)
        self._links = [Link(t, _resolve(t.to)) for t in cfg.resolved_targets()]
        self.address = "OSC to " + ", ".join(f"udp {t.to} ({t.profile})" for t in cfg.resolved_targets())
        self._sample_links = [link for link in self._links if not link.target.framed]
        self._frame_links = [link for link in self._links if link.target.framed]
        self._held = [link.held for link in self._links]  # (each target's, read as a whole a frame)
        # id(Selected) → it (kept, so its id is not reused) and each target with its plan for its frames
        self._lanes: Capped[int, tuple[Selected, tuple[tuple[Link, Plan | None], ...]]] = Capped(
            MAX_PLANS, MAX_PLAN_BYTES * len(self._links))  # (the bytes of a plan a target, as each target kept them)
        self._assembler = FrameAssembler()
        self.stats.follow("late", lambda: self._assembler.late)
        self._tally = self.stats.tally(("received", "sent"))  # (counted under self._state: no lock of their own)
        self._max_age = cfg.max_age_ms / 1000.0
        self._count, self._warn = self._counted, self.warn  # (bound once: passed on with every frame)
        for link in self._links:
            self.own(link.socket)
        self._queue = self.own(SampleQueue(cfg.queue))
        self._presence = presence.connection_events(self.bus, self._queue, cfg.subscribe,
                                                    self.capped)  # a robot's loss, return
        lateness.follow(self.bus)  # (where each robot's node runs: a stale sample's warning names the likely cause)
        # Frames are taken where they arrive (a thread hand-off less: docs/performance.md), the rest
        # from the queue by the forward worker; one lock between them guards the sink's state.
        self._state = threading.Lock()
        # (what a frame taken where it arrived can leave held for the worker: a target's turn, a bundle's parts)
        self._may_hold = bool(self._frame_links) or any(link.min_interval for link in self._links)
        self._until = _FOREVER  # when the forward worker wakes by itself (set by it, under _state)
        self._working = False  # the forward worker holds _state, taking a batch
        self._streams: Streams | None = None  # (a frame may arrive while Streams subscribes: queued, see _direct)
        self._streams = Streams(self.bus, cfg.subscribe, self._queue, per_joint_keys=cfg.per_joint_keys,
                                direct=self._direct)
        self.when_stopping(self._queue.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._forward, "forward")
        self.own(self._streams)
        self.own(self._presence)
        self.when_stopping(self._presence.wake)
        self.spawn(lambda: self._presence.watch(self.stopping), "silence")

    @property
    def dropped(self) -> int:
        """Samples dropped because the queue was full."""
        return self._queue.dropped

    def metrics(self) -> dict[str, Any]:
        """Datagrams sent per target."""
        sent: dict[str, int] = {}
        for link in getattr(self, "_links", ()):
            sent[link.target.to] = sent.get(link.target.to, 0) + link.sent
        return {"sent_to": sent}

    # -- the loop ---------------------------------------------------------------------

    def _forward(self) -> None:
        """The queue's messages, and what is held (a frame's parts, a target's turn) when it is due:
        the worker sleeps until then, or until a message comes or the stop closes the queue."""
        while not self.stopping.is_set():
            with self._state:
                wait = self._wait()
                self._until = _FOREVER if wait is None else time.monotonic() + wait
            items = self._queue.drain(timeout=wait)
            with self._state:
                self._working = True
                try:
                    now = time.monotonic()  # (once the lock is had: a frame taken where it arrived may have held it)
                    for item in items:
                        self._take(*item, now)
                    self._tick(now)
                finally:
                    self._working = False

    def _direct(self, key: str, payload: Any) -> bool:
        """A frame, on its subscription's callback thread (``Streams``' ``direct``), taken there
        (``_take``, under ``_state``); into the queue instead (False) before it subscribed
        everywhere or while the forward worker takes a batch (``if_free``: a batch may take
        seconds, Zenoh's threads must not wait). What it held (a target's turn, a frame's parts)
        due before the worker would wake wakes it (``SampleQueue.wake``)."""
        # (``if_free`` without its call and lambda a frame, nor a call of its own for the take: the
        # dispatch is every frame's, issue 35)
        # (held but not by the worker: by the other subscription's callback taking its frame, a derived
        # frame and its robot's arriving together, a matter of µs: waited for, where the queue cost the
        # worker's wake-up for a third of the show's derived frames, issue 35; not long even if the worker
        # took the lock in between)
        state = self._state
        if self._streams is None or not (state.acquire(blocking=False)
                                         or (not self._working and state.acquire(timeout=DIRECT_WAIT_S))):
            return False
        try:
            self._take(key, payload, time.monotonic())
            # (``_wait`` only when something is held: a frame sent whole holds nothing, issue 35)
            if self._may_hold and (self._assembler.open or any(self._held)) and (wait := self._wait()) is not None \
                    and time.monotonic() + wait < self._until:
                self._until = _NEVER  # (woken once)
                self._queue.wake()
        finally:
            state.release()
        return True

    def _wait(self) -> float | None:
        """Until the soonest held thing is due; None with nothing held."""
        soonest = []
        expiry = self._assembler.next_expiry()
        if expiry is not None:
            soonest.append(expiry)
        for link in self._links:
            if link.held:
                soonest.append(min(link.last_sent.get(s, 0.0) for s in link.held) + link.min_interval)
        return max(0.0, min(soonest) - time.monotonic()) if soonest else None

    def _tick(self, now: float) -> None:
        for frame in self._assembler.expire(now):
            self._send_frame(frame, now)
        for link in self._links:
            for slot in [s for s in link.held if link.turn(s, now)]:
                held = link.held.pop(slot)
                if isinstance(held, Frame):
                    self._frame_to(link, held, now)
                else:
                    self._sample_to(link, *held, now)

    def _counted(self, kind: str, n: int = 1) -> None:
        """``count``, under ``_state``: what every frame counts goes to the tally."""
        if kind == "received":
            self._tally[kind] += n
        else:
            self.count(kind, n)

    def _take(self, key: str, payload: Any, now: float) -> None:
        message = self._streams.take(key, payload, self._count, self._warn, now)
        if message is None:
            return
        source = message.source
        if source.section in ("frame", "joints") and now - self._heard.get(source.robot, _NEVER) >= HEARD_EVERY_S:
            if len(self._heard) >= 4096:  # (robot names come from the network)
                self._heard.clear()
            self._heard[source.robot] = now
            self._presence.heard_from(source.robot)
        if message.event is not None:
            if self._presence.passes(source.robot, message.event):  # (a repeated connection state: not)
                self._event(source, message.event)
            return
        t = message.t
        if self._max_age and time.time() - t > self._max_age:
            self.count("stale")
            self.warn("stale", f"samples older than max_age_ms = {self.config.max_age_ms:g} dropped ('{key}' was "
                               f"{(time.time() - t) * 1000:.0f} ms old: {lateness.why_late(self.bus, source.robot)})")
            return
        if message.parts is not None:  # a derived frame: its values, as the samples of their keys
            if message.parts:
                self._derived(message.parts, now)
        elif message.selected is None:
            self._samples((message,), now)
        elif message.values:
            self._frame(message, now)
        # once a message, however many targets (Adapter.record_latency's, without its call)
        self._stats_report.latencies.add(time.time() - t)

    def _samples(self, samples: Sequence[Incoming], now: float, framed_only: bool = False) -> None:
        """The general path: samples (joint keys, derived values), one target and one value at a time
        (``framed_only``: to the targets of whole frames only)."""
        for link in () if framed_only else self._sample_links:
            for sample in samples:
                self._sample_to(link, sample.source, sample.values, sample.t, sample.seq, now)
        if self._frame_links:
            # Joints and derived values of one seq go out in one bundle, however they came.
            first = samples[0]
            frames = self._assembler.extend(first.source.robot, first.seq, first.t,
                                            {s.source.key: (s.source, s.values) for s in samples})
            for frame in frames:
                self._send_frame(frame, now)

    def _derived(self, parts: Parts, now: float) -> None:
        """A derived frame's values: each target of plain messages from its plan for them, where
        it has one; the general path (``_samples``, a value at a time) for the others."""
        for link in self._sample_links:
            if not self._planned_derived(link, parts):
                for sample in parts:
                    self._sample_to(link, sample.source, sample.values, sample.t, sample.seq, now)
        if self._frame_links:
            self._samples(parts, now, framed_only=True)

    def _planned_derived(self, link: Link, parts: Parts) -> bool:
        """Send a derived frame's values (``parts``) to ``link`` from its plan (``DerivedBytes``,
        a message each: what ``_sample_to`` sends of each value, through ``sample``); False when
        it takes the general path: a rate cap, a filter, normalized values, a value OSC cannot carry."""
        if not link.derived_direct:
            return False
        sources, values = parts.sources, parts.values
        entry = link.derived_plans.get(id(sources))
        if entry is None or entry[0] is not sources:
            entry = link.derived_plans.put(id(sources), (sources, link.profile.compile_derived(sources, shape_of(
                values))), size_of(s.key for s in sources))  # (its addresses: about its keys)
        found = entry[1]
        if found is None:
            return False
        try:
            datagrams = found.render(parts.t, parts.seq, values)
        except _NOT_PLANNED:
            shape = shape_of(values)
            if shape == found.shape:  # (a value OSC cannot carry: the general path leaves out just that one)
                return False
            # (its values' sizes changed: planned again for them, as the first frame's were)
            entry = link.derived_plans.put(id(sources), (sources, link.profile.compile_derived(sources, shape)),
                                           size_of(s.key for s in sources))
            if entry[1] is None:
                return False
            try:
                datagrams = entry[1].render(parts.t, parts.seq, values)
            except _NOT_PLANNED:
                return False
        self._emit(link, datagrams)
        return True

    def _frame(self, message: Incoming, now: float) -> None:
        """A robot's frame: each target's datagrams from its plan for these joints (its lane's),
        where it has one; the general path (``_unplanned``) for the others. A frame that is not
        whole by itself (derived values of its seq join it) goes to the targets of whole frames
        once complete (``_assemble``)."""
        selected = message.selected
        lane = self._lanes.get(id(selected))
        if lane is None or lane[0] is not selected:
            lane = self._lane(selected, message.source.robot)
        whole = None  # (asked once, at the first target of whole frames)
        for link, plan in lane[1]:
            if link.framed:
                if whole is None:
                    whole = self._assembler.whole(message.source.robot, message.seq, message.t, selected.keys)
                    if not whole:
                        self._assemble(message, now)
                if not whole:
                    continue
            if plan is None or not self._planned(link, plan, message, now):
                self._unplanned(link, message, now)

    def _lane(self, selected: Selected, robot: str) -> tuple[Selected, tuple[tuple[Link, Plan | None], ...]]:
        """The frames of ``selected`` joints' lane: every target with its plan for them (None: the
        general path), worked out once for a joint list (kept by the identity of ``selected``, which
        the lane holds so it is not reused; worked out again once ranges come). One lookup a frame,
        not one a target (issue 35)."""
        plans = tuple((link, self._plan(link, selected, robot) if link.direct else None) for link in self._links)
        return self._lanes.put(id(selected), (selected, plans),  # (its addresses: about its keys, a target each)
                               len(plans) * size_of(s.key for s in selected.sources))

    def _assemble(self, message: Incoming, now: float) -> None:
        """A frame joined by the derived values of its seq: to every target of whole frames once complete."""
        selected = message.selected
        assert selected is not None
        items = {s.key: (s, (v,)) for s, v in zip(selected.sources, message.values, strict=True)}
        for frame in self._assembler.extend(message.source.robot, message.seq, message.t, items):
            self._send_frame(frame, now)

    def _unplanned(self, link: Link, message: Incoming, now: float) -> None:
        """A frame to ``link`` by the general path: a joint at a time (``_sample_to``), or as a
        ``Frame`` (``_frame_link``, its turn and its filter) to a target of whole frames."""
        if not link.framed:
            for sample in message.samples:
                self._sample_to(link, sample.source, sample.values, sample.t, sample.seq, now)
            return
        selected = message.selected
        assert selected is not None
        self._frame_link(link, Frame(message.source.robot, message.seq, message.t, {
            s.key: (s, (v,)) for s, v in zip(selected.sources, message.values, strict=True)}), now)

    def _planned(self, link: Link, plan: Plan, message: Incoming, now: float) -> bool:
        """Send ``message`` (a frame) to ``link`` from its ``plan``; False when a value OSC cannot
        carry sends it by the general path instead (which leaves out just that one, and says so)."""
        values: Sequence[float] = message.values
        if plan.spans is not None:
            fraction = scale.fraction
            values = [v if span is None else fraction(v, span) for v, span in zip(values, plan.spans, strict=True)]
        t = message.t
        if not link.framed:
            try:
                datagrams = plan.datagrams.render(t, message.seq, values)
            except _REFUSED:
                return False
            self._emit(link, datagrams)
            return True
        robot = message.source.robot
        previous = link.last_frame_t.get(robot)
        try:
            datagrams = plan.datagrams.render(t, message.seq, values,
                                              t - previous if previous is not None and t > previous else 0.0)
        except _REFUSED:
            return False
        link.last_sent[robot] = now
        link.last_frame_t[robot] = t
        self._emit(link, datagrams)
        return True

    def _plan(self, link: Link, selected: Selected, robot: str) -> Plan | None:
        """``link``'s plan for frames of ``selected`` joints (None: the general path, which
        waits for the robot's ranges, or says what OSC cannot carry)."""
        spans = None
        if link.target.values != "raw":
            ranges = self._ranges.spans.get(robot)
            if ranges is None:
                return None
            spans = tuple(ranges.get(source.name) for source in selected.sources)
        datagrams = link.profile.compile(selected.sources)
        return None if datagrams is None else Plan(datagrams, spans)

    # -- per target ------------------------------------------------------------------

    def _sample_to(self, link: Link, source: Key, values: Sequence[float], t: float, seq: int,
                   now: float) -> None:
        key = source.key
        if link.min_interval and not link.turn(key, now):
            link.held[key] = (source, values, t, seq)  # filtered when its turn comes
            return
        scaled = self._scaled(link, source, values)
        if scaled is None or (link.filtering and not link.changed(key, scaled)):
            return
        if link.min_interval:
            link.last_sent[key] = now
        self._send(link, link.profile.sample, source, scaled, t, seq)

    def _send_frame(self, frame: Frame, now: float) -> None:
        for link in self._frame_links:
            self._frame_link(link, frame, now)

    def _frame_link(self, link: Link, frame: Frame, now: float) -> None:
        if link.turn(frame.robot, now):
            self._frame_to(link, frame, now)
        else:
            link.held[frame.robot] = frame

    def _frame_to(self, link: Link, frame: Frame, now: float) -> None:
        samples = []
        for source, values in frame.values.values():
            scaled = self._scaled(link, source, values)
            if scaled is not None and link.changed(source.key, scaled):
                samples.append((source, scaled))
        if not samples:
            return
        link.last_sent[frame.robot] = now
        previous = link.last_frame_t.get(frame.robot)
        link.last_frame_t[frame.robot] = frame.t
        interval = frame.t - previous if previous is not None and frame.t > previous else 0.0
        self._send(link, link.profile.frame, frame.robot, frame.t, frame.seq, samples, interval)

    def _event(self, source: Key, message: dict[str, Any]) -> None:
        kind = str(message.get("kind") or source.name)
        for link in self._links:
            if link.target.events:
                self._send(link, link.profile.event, source.robot, kind, message)

    def _send(self, link: Link, render: Callable[..., bytes | Rendered | None], *args: Any) -> None:
        """Encode with ``render(*args)`` and send; what OSC cannot carry is left out
        (just that message: the rest of a frame or bundle goes), counted and warned about."""
        try:
            rendered = render(*args)
        except EncodeError as exc:
            self._unencodable(link, [exc])
            return
        if isinstance(rendered, tuple):
            rendered, dropped = rendered
            if dropped:
                self._unencodable(link, dropped)
        self._emit(link, [rendered] if isinstance(rendered, bytes) else rendered or ())

    def _emit(self, link: Link, datagrams: Sequence[bytes]) -> None:
        """Send ``datagrams`` to ``link``'s target, counted once."""
        send, sent = link.send, 0
        for datagram in datagrams:
            try:
                send(datagram)
                sent += 1
            except ConnectionRefusedError:  # an earlier datagram's "port unreachable"; this one was not sent
                self._refused(link)
                try:
                    send(datagram)  # (the error is reported once: this one goes)
                    sent += 1
                except OSError as exc:
                    self._send_failed(link, exc)
            except OSError as exc:
                self._send_failed(link, exc)
        if sent:
            link.sent += sent
            self._tally["sent"] += sent
            if link.refused_at and time.monotonic() - link.refused_at > LISTENING_AFTER_S:
                link.refused_at = 0.0
                log.info("%s: something listens at udp %s now", self.name, link.target.to)

    def _refused(self, link: Link) -> None:
        """Nothing listens at ``link``'s target: counted, and said once until something does."""
        self.count("unreachable")
        if not link.refused_at:
            log.warning("%s: nothing listens at udp %s (its host answered 'port unreachable'): start the "
                        "receiver there, or check the port; sending on, it gets the stream once it listens",
                        self.name, link.target.to)
        link.refused_at = time.monotonic()

    def _send_failed(self, link: Link, exc: OSError) -> None:
        self.count("send_errors")
        self.warn("send", f"cannot send to {link.target.to}: {exc.strerror or exc}")

    def _unencodable(self, link: Link, dropped: list[EncodeError]) -> None:
        self.count("unencodable", len(dropped))
        self.warn("encode", f"left out of what goes to {link.target.to}, OSC cannot carry it: {dropped[0]}"
                  + (f" (and {len(dropped) - 1} more)" if len(dropped) > 1 else ""))

    # -- normalization ----------------------------------------------------------------

    def _scaled(self, link: Link, source: Key, values: Sequence[float]) -> Sequence[float] | None:
        if link.target.values == "raw":
            return values
        scaled = self._ranges.scaled(source, values)
        if scaled is None:  # (its robot's info, or a word of it on this derived value, to come)
            self.count("waiting_info")
            self._info.ask(source.robot)
        return scaled

    def _take_info(self, robot: str, info: dict[str, Any]) -> None:
        try:
            spans = scale.ranges(info)  # (not under _state: an info may be large, frames wait on it)
        except (KeyError, TypeError, ValueError) as exc:
            self.warn("info", f"{robot}/info unusable: {exc}")
            return
        with self._state:
            if not self._ranges.keep(robot, info, spans):
                self.capped(f"robot '{robot}': its info not kept, already {MAX_ROBOTS} robots' (its values go out "
                            "raw to targets of raw values, not at all to those of normalized ones)")
                return
            self._lanes.clear()  # (worked out again with these ranges)
            for link in self._links:
                link.derived_plans.clear()


def _resolve(target: str) -> tuple[str, int]:
    host, port = parse_target(target)
    try:
        return socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4][:2]
    except socket.gaierror as exc:
        raise ConfigError(f"target '{target}': cannot resolve '{host}': {exc.strerror}") from None
