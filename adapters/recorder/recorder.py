"""``recorder``: what ``subscribe`` selects on the bus into MCAP files, beside a
live installation and without slowing it down, for days.

    [nodes.logger]
    adapter = "recorder"
    path = "recordings/show-{time}.mcap"      # {time}: when each file starts, 20261122-140501
    rotate_s = 3600                           # a new file every hour (and/or rotate_mb)

Joints come as frames (``<robot>/frame``, one Zenoh sample per frame; see
``bus/streams.py``) and each is written whole, one MCAP message with the joints
``subscribe`` selects (issue 35: it was a message per joint key); ``Recording``
reads it as the samples of those keys, so what a reader gets is what it got
from a file of before. ``per_joint_keys = true`` records joint keys as
published instead (publishers that put no frames).

Unless ``foxglove = false`` it also writes the views Foxglove's panels read
(``adapters/foxglove/views.py``): ``<robot>/log``
(events as ``foxglove.Log``), ``<robot>/tf`` (the arms as
``foxglove.FrameTransforms``, every frame, once the robot's info names a model
with kinematics) and ``<robot>/info/derived`` (what feature processors answer
there: the derived keys' units and ranges); the frames themselves are Foxglove's
``<robot>/frame``. They are counted in ``foxglove``, not ``written`` (a frame
counts as its joints there); readers of bus data (replay, export, plot) leave
them out.

Audio is recorded only when a pattern names it (``*/audio/mic``: the robot's
microphones, ``*/audio/speaker``), a channel per key holding each chunk as
msgpack (``channels.encoding_of``); the recorder then says at start, in one
warning, that it records microphones. ``sonibus export --wav`` makes WAV files
of them (``wav.py``).

Files (``rotation.py``): a new one every ``rotate_s`` and/or at ``rotate_mb``,
each finished with its summary and starting with the robots' info, so each
stands alone; no message is lost or written twice across a change of file
(the one writer thread changes file between two messages). While a file is
written the recorder holds its lock (``lock.py``): ``sonibus info`` tells it
from a torn one.

The disk guard (``disk.py``): below ``warn_free_mb`` free, one warning; below
``min_free_mb`` the file is finished and the recorder pauses (state
``paused``, a ``node`` event, ``sonibus nodes`` says why) while the rest of the
installation goes on; it records again, into a new file, once twice
``min_free_mb`` is free. A write that fails all the same (the disk filled
faster than the guard looks, an I/O error) pauses it as well, the file only
closed (``sonibus recover``), and it tries again every ``RETRY_S``.

Messages wait in the recorder's own bounded queue; if the disk cannot keep up
the oldest are dropped and counted (``stats["dropped"]``), never silently; what
comes while it is paused is counted in ``unrecorded``. A message the gate or
the writer refuses is counted in ``bad`` and skipped. A recorder that hears
nothing for ``quiet_warn_s`` says so once, with the likeliest cause. A
``path`` that cannot be written is a ``ConfigError`` when the node is
configured or, at the latest, started.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import zenoh

from sonibus.adapters.foxglove.views import DERIVED_INFO, Views, selected
from sonibus.bus import codec, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import ConfigError
from sonibus.bus.info import InfoRequests
from sonibus.bus.options import bad
from sonibus.bus.ownership import claims
from sonibus.bus.plan import named_section
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

from .disk import MB, DiskGuard
from .rotation import TIME, Rotation, Series
from .writer import BadRecord, WriteError, unwritable

log = logging.getLogger(__name__)

EVERYTHING = ("*/joints/*", "*/derived/**", "*/events/*")  # no audio: microphones only when named
MICROPHONES = "*/audio/mic"
DISK_EVERY_S = 1.0   # how often the disk guard looks at the free space
RETRY_S = 10.0       # a recorder paused by a failed write tries a new file this often (once space allows)
GATHER_S = 0.05      # the writer takes what came at most this often (a wake-up costs ~50-90 µs on a small VM)
UNDECLARED_S = 2.0   # at stop, how long the writer waits for the subscriptions to end before its last drain


@dataclass(frozen=True)
class RecorderConfig:
    path: str
    subscribe: tuple[str, ...] = EVERYTHING   # robot info is always recorded, once per robot and file
    overwrite: bool = False                   # replace a file at a fixed path (a {time} path never replaces)
    rotate_s: float = 0.0                     # a new file every rotate_s seconds; 0: never (needs {time})
    rotate_mb: float = 0.0                    # a new file once one holds rotate_mb MB; 0: no limit (needs {time})
    warn_free_mb: float = 2000.0              # a warning when the disk has less free (about a day of one robot)
    min_free_mb: float = 200.0                # the file finished and recording paused below this; 0: never
    quiet_warn_s: float = 60.0                # one warning, with the likely cause, after this long hearing nothing
    queue: int = 1 << 16                      # messages waiting for the disk (a frame is one: minutes of two robots)
    flush_s: float = 1.0                      # at most this much is lost if the recorder is killed
    status_every_s: float = 10.0              # a log line with what has been recorded; 0: none
    per_joint_keys: bool = False              # joints from <robot>/joints/* instead of <robot>/frame (bus/streams.py)
    foxglove: bool = True                     # also the views Foxglove reads: <robot>/frame, /log, /tf, /info/derived

    def __post_init__(self) -> None:
        if not self.path:
            raise bad("path", "is empty — name the .mcap file to write")
        object.__setattr__(self, "subscribe", keys.patterns(self.subscribe))
        for key in ("rotate_s", "rotate_mb", "min_free_mb", "quiet_warn_s"):
            if not getattr(self, key) >= 0:
                raise bad(key, f"{getattr(self, key)} must be 0 or more")
        if 0 < self.rotate_s < 1:
            raise bad("rotate_s", f"{self.rotate_s} is under a second — a file's name says its second")
        if (self.rotate_s or self.rotate_mb) and TIME not in self.path:
            rotates = "rotate_s" if self.rotate_s else "rotate_mb"
            stem, extension = os.path.splitext(self.path)
            raise bad("path", f"'{self.path}' has no {TIME}, and {rotates} starts new files: each is named by "
                              f"when it starts — e.g. '{stem}-{TIME}{extension or '.mcap'}'")
        if not self.warn_free_mb >= self.min_free_mb:
            raise bad("warn_free_mb", f"{self.warn_free_mb} is below min_free_mb {self.min_free_mb} — the warning "
                                      "comes before recording stops")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        if not self.flush_s > 0:
            raise bad("flush_s", f"{self.flush_s} must be more than 0")
        problem = unwritable(self.path.replace(TIME, "0"))
        if problem:
            raise bad("path", problem)

    @property
    def microphones(self) -> tuple[str, ...]:
        """The patterns that record a robot's microphones."""
        mic = zenoh.KeyExpr(MICROPHONES)
        return tuple(p for p in self.subscribe if named_section(p) == "audio" and zenoh.KeyExpr(p).intersects(mic))


class Recorder(Adapter):
    """Records joints, derived values, events and robot info (audio when named) into MCAP files."""

    Config = RecorderConfig
    counters = ("written", "unrecorded")

    def _start(self) -> None:
        cfg: RecorderConfig = self.config
        self._undeclared = threading.Event()  # set by ``_stop``: nothing more comes into the queue
        self.paused = ""  # why the recorder is not writing, while it is not
        self._wall0, self._mono0 = time.time_ns(), time.monotonic_ns()
        metadata = {"host": self.bus.host, "node": self.name, "subscribe": " ".join(cfg.subscribe)}
        self._series = Series(self.resolve(cfg.path), Rotation(cfg.rotate_s, cfg.rotate_mb), metadata, cfg.flush_s)
        self.path = self.address = self._series.first(time.time())
        if os.path.exists(self.path) and TIME not in cfg.path and not cfg.overwrite:
            raise ConfigError(f"{self.path} exists — choose another name, or overwrite it "
                              "(--overwrite, overwrite = true)")
        if cfg.microphones:
            log.warning("%s: records the microphones (%s): what visitors say near the robot goes into %s — "
                        "a venue needs their consent (docs/recorder.md, \"Audio\")", self.name,
                        " ".join(cfg.microphones), self.path)
        self._disk = DiskGuard(cfg.warn_free_mb, cfg.min_free_mb)
        self._disk_checked = self._retry_at = time.monotonic()
        self._heard, self._heard_at, self._quiet_said = 0, time.monotonic(), False
        self._queue = self.own(SampleQueue(cfg.queue))
        self._info_seen: set[str] = set()
        if self._disk.check(self._folder()) == "full":
            self._pause(self._full(), guard=True)
        else:
            self._warn_low()
            self._open(first=True)
        self._views = Views(self.bus, self._take_derived_info) if cfg.foxglove else None
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: log.warning("%s", text))
        try:
            self._streams = Streams(self.bus, cfg.subscribe, self._queue, per_joint_keys=cfg.per_joint_keys,
                                    stamped=True, pace=False)  # a recording keeps every frame, bursts too
        except BaseException:
            self._series.close(dict(self.stats))
            raise
        self._last_status = time.monotonic()
        self.spawn(self._write, "write")

    def _open(self, first: bool = False) -> None:
        """The next file of the series; a path that cannot be written is a configuration
        error at start (rather than at the first chunk), a ``WriteError`` later."""
        try:
            carried = self._series.open(self._now_ns(), dict(self.stats))
        except (OSError, WriteError) as exc:
            reason = exc if isinstance(exc, WriteError) else WriteError(
                f"cannot write {self._series.path or self.path}: {exc.strerror or exc}")
            if not first:
                raise reason from None
            raise ConfigError(f"node '{self.name}': key 'path': {reason} — "
                              "choose a folder that exists or can be created, and that you can write to") from None
        self.path = self.address = self._series.path
        if carried:
            log.info("%s: %s starts with the robots' info", self.name, self.path)

    def _stop(self) -> None:
        try:
            if hasattr(self, "_streams"):  # first, so the writer drains all that came
                self._streams.undeclare()
        finally:
            if hasattr(self, "_undeclared"):
                self._undeclared.set()

    def describe(self) -> dict[str, Any]:
        """As every node's, and while paused why (``failure``: what ``sonibus nodes`` and ``top``
        show beside a state that is not ``running``)."""
        described = super().describe()
        if getattr(self, "paused", "") and not self.failure:
            described["failure"] = self.paused
        return described

    def status(self) -> dict[str, Any]:
        """What has been recorded so far."""
        elapsed = (time.monotonic_ns() - self._mono0) / 1e9
        return {"path": self.path, "files": self._series.files, "duration_s": elapsed,
                "messages": self.stats["written"], "rate": self.stats["written"] / elapsed if elapsed > 0 else 0.0,
                "bytes": self._series.bytes, "dropped": self._queue.dropped, "bad": self.stats["bad"],
                "unrecorded": self.stats["unrecorded"], "paused": self.paused, "failure": self.failure,
                "views": self.stats.get("foxglove", 0)}

    @property
    def files(self) -> list[str]:
        """Every file this recorder started, in order."""
        return list(self._series.paths)

    def metrics(self) -> dict[str, Any]:
        """The file, its size so far, the files written, the free space; why it is paused."""
        series = getattr(self, "_series", None)
        if series is None:
            return {}
        writer = series.writer
        figures: dict[str, Any] = {"path": self.path, "bytes": writer.size if writer is not None else 0,
                                   "files": series.files}
        if self._disk.free is not None:
            figures["free_mb"] = round(self._disk.free / MB, 1)
        if self.paused:
            figures["paused"] = self.paused
        return figures

    def _take_info(self, robot: str, info: dict[str, Any]) -> None:  # on a Zenoh thread
        self._queue.put((keys.info(robot), codec.encode(info), time.monotonic_ns()))

    def _take_derived_info(self, key: str, payload: bytes) -> None:  # on a Zenoh thread
        self._queue.put((key, payload, time.monotonic_ns()))

    # -- the writer thread ----------------------------------------------------------------

    def _write(self) -> None:
        try:
            while not self.stopping.is_set():
                batch = self._queue.drain(timeout=0.2)
                for item in batch:
                    self._take(*item)
                self._tick()
                if batch:  # (what comes meanwhile waits, stamped: one wake-up a batch, not one a message)
                    self.stopping.wait(GATHER_S)
            # (stop wakes the writer before the subscriptions end: what they still queue meanwhile is
            # taken too, not left in a queue nobody reads — with the 50 ms gathering, most stops lost some)
            self._undeclared.wait(UNDECLARED_S)
            while (item := self._queue.get(timeout=0)) is not None:  # what arrived before stop
                self._take(*item)
            self._series.close(dict(self.stats))
        except WriteError as exc:  # at the last close: said, nothing left to pause
            self.paused = str(exc)
            log.error("%s: %s", self.name, exc)
        except BaseException:
            # Raised again for the base class to fail the node loudly. The file is finished if it
            # is sound, else only closed: recover then keeps its complete chunks.
            with contextlib.suppress(WriteError):
                self._series.close(dict(self.stats))
            raise
        log.info("%s: %s", self.name, describe(self.status()))

    def _take(self, key: str, payload: bytes, arrived_ns: int) -> None:
        """One message from the queue, in the file of its time (a file changes between two)."""
        try:
            if why := self._series.due():
                self._rotate(why)
            self._record(key, payload, arrived_ns)
        except WriteError as exc:
            self._pause(str(exc), guard=False)

    def _tick(self) -> None:
        """Between messages, at least every 0.2 s: a file's time, the disk, a silence, the status line."""
        now = time.monotonic()
        try:
            if why := self._series.due():
                self._rotate(why)
            if now - self._disk_checked >= DISK_EVERY_S:
                self._disk_checked = now
                self._look_at_disk(now)
        except WriteError as exc:
            self._pause(str(exc), guard=False)
        self._listen(now)
        self._report()

    def _rotate(self, why: str) -> None:
        done = self.path
        self._series.close(dict(self.stats))
        self._open()
        log.info("%s: %s done (%s); now %s", self.name, done, why, self.path)

    def _look_at_disk(self, now: float) -> None:
        level = self._disk.check(self._folder())
        if level == "full" and not self.paused:
            self._pause(self._full(), guard=True)
        elif level == "low":
            self._warn_low()
        free = self._disk.free  # (None: a file system that does not say; trying is the only way to know)
        if self.paused and now >= self._retry_at and (free is None or free >= self._disk.resume):
            self._resume()

    def _full(self) -> str:
        return (f"the disk is nearly full: {self._disk.describe(self._folder())}, below min_free_mb "
                f"{self.config.min_free_mb:g} — free some space; recording goes on by itself, into a new file, "
                f"once {self._disk.resume / MB:g} MB are free")

    def _warn_low(self) -> None:
        cfg: RecorderConfig = self.config
        if self._disk.level != "low":
            return
        elapsed = (time.monotonic_ns() - self._mono0) / 1e9
        left = self._disk.left(self._series.bytes / elapsed if elapsed > 1 else 0.0)
        log.warning("%s: %s, below warn_free_mb %g: recording pauses at min_free_mb %g%s — free some space, "
                    "or record elsewhere (path)", self.name, self._disk.describe(self._folder()), cfg.warn_free_mb,
                    cfg.min_free_mb, f" ({left})" if left else "")

    def _pause(self, why: str, guard: bool) -> None:
        """Stop writing (the file finished, or only closed after a failed write) and say so;
        the rest of the installation goes on."""
        try:
            self._series.close(dict(self.stats))
        except WriteError as exc:
            why = f"{why}; and {exc}" if guard else why
        if self.paused:
            self.paused = why
            return
        self.paused = why
        self._retry_at = time.monotonic() + (0.0 if guard else RETRY_S)
        if self.state in ("starting", "running"):
            self.state = "paused"
        log.warning("%s: recording paused: %s", self.name, why)
        self._node_event("paused", why)

    def _resume(self) -> None:
        try:
            self._open()
        except WriteError as exc:
            self.paused = str(exc)
            self._retry_at = time.monotonic() + RETRY_S
            self.warn("retry", f"recording still paused: {exc}; trying again in {RETRY_S:g} s")
            return
        self.paused = ""
        if self.state == "paused":
            self.state = "running"
        log.warning("%s: recording again, into %s (%s)", self.name, self.path, self._disk.describe(self._folder()))
        self._node_event("running", "")

    def _node_event(self, state: str, why: str) -> None:
        event = {"t": time.time(), "kind": "node", "host": self.bus.host, "node": self.name, "adapter": self.kind,
                 "state": state, "path": self.path}
        if why:
            event["error"] = why
        try:
            self.bus.put(keys.NODE_EVENTS, event)
        except Exception as exc:  # (a session closing): the log line and the state remain
            log.debug("%s: node event not sent: %s", self.name, exc)

    def _listen(self, now: float) -> None:
        """One warning, with the likeliest cause, once nothing has come for ``quiet_warn_s``."""
        quiet_s = self.config.quiet_warn_s
        if self.stats["received"] != self._heard:
            self._heard, self._heard_at, self._quiet_said = self.stats["received"], now, False
        elif quiet_s and not self._quiet_said and now - self._heard_at >= quiet_s:
            self._quiet_said = True
            self.warn("quiet", self._quiet_cause(now - self._heard_at))

    def _quiet_cause(self, silent_s: float) -> str:
        what = " ".join(self.config.subscribe)
        try:
            robots = sorted(claims(self.bus.alive(keys.robot_token(), timeout=1.0)))
        except Exception as exc:  # (a session closing)
            return f"nothing to record for {silent_s:.0f} s ({what}); robots on the bus unknown: {exc}"
        if not robots:
            return (f"nothing to record for {silent_s:.0f} s: no robot is on the bus — is its node running, and on "
                    "this bus (sonibus nodes; the [bus] table's mode, connect and namespace)?")
        return (f"nothing to record for {silent_s:.0f} s though {', '.join(robots)} "
                f"{'is' if len(robots) == 1 else 'are'} on the bus: a robot that is not connected sends nothing "
                f"(sonibus nodes), or subscribe ({what}) selects nothing it publishes")

    def _record(self, key: str, payload: bytes, arrived_ns: int) -> None:
        log_ns = self._wall0 + arrived_ns - self._mono0
        if self._views is not None and key.endswith("/" + DERIVED_INFO):  # (an answer the views asked for)
            self._derived_info(self._views, key, payload, log_ns)
            return
        incoming = self._streams.take(key, payload, self.count, self.warn)  # checked by the gate, counted
        if incoming is None:
            return
        framed = incoming.source.section == "frame"
        # a frame is written whole, its selected joints, one message (issue 35: was a message per joint)
        samples = ([(key, selected(incoming))] if incoming.values else []) if framed else [(key, incoming.message)]
        # counted as readers give them (Recording.counts): a frame's joints, a derived frame's values
        held = len(samples[0][1]["names"]) if samples and (framed or keys.is_derived_frame(key)) else len(samples)
        robot = key.partition("/")[0]
        if key.endswith("/info"):
            if robot in self._info_seen:
                return
            self._info_seen.add(robot)
            self._series.carry(key, incoming.message)  # (each file starts with it: it stands alone)
        elif robot not in self._info_seen:
            self._info.ask(robot)
        if self._series.writer is None:  # paused
            self.count("unrecorded", held)
            return
        views = self._views.of(incoming, frame=not framed, whole=samples[0][1] if framed and samples else None) \
            if self._views is not None else []
        refused = self._series.writer.write_all([*samples, *views], log_ns)  # (in one go: issue 35)
        for refused_key, exc in refused:  # (past the gate, rare): skipped whole, the file stays readable
            self.count("bad")
            self.warn("unwritable", f"message on '{refused_key}' not recorded: {exc}")
        gone = {refused_key for refused_key, _ in refused}
        if samples and samples[0][0] not in gone:
            self.count("written", held)
        if views:
            self.count("foxglove", sum(view not in gone for view, _ in views))

    def _put(self, key: str, log_ns: int, message: dict[str, Any]) -> bool:
        """Write one message; one the writer refuses is counted ``bad`` and skipped."""
        writer = self._series.writer
        if writer is None:
            return False
        try:
            writer.write(key, log_ns, message)
        except BadRecord as exc:  # (past the gate, rare): skipped whole, the file stays readable
            self.count("bad")
            self.warn("unwritable", f"message on '{key}' not recorded: {exc}")
            return False
        return True

    def _derived_info(self, views: Views, key: str, payload: bytes, log_ns: int) -> None:
        """What a feature processor answered on ``<robot>/info/derived``, checked by the gate."""
        try:
            message = views.derived_info(key, payload)
        except ValueError as exc:  # messages.BadMessage
            self.count("bad")
            self.warn("bad", f"message on '{key}' refused: {exc}")
            return
        self._series.carry(key, message)
        if self._put(key, log_ns, message):
            self.count("foxglove")

    def _report(self) -> None:
        every = self.config.status_every_s
        if every and time.monotonic() - self._last_status >= every:
            self._last_status = time.monotonic()
            log.info("%s: %s", self.name, describe(self.status()))

    def _now_ns(self) -> int:
        return self._wall0 + time.monotonic_ns() - self._mono0

    def writes(self) -> list[str]:
        return [os.path.dirname(os.path.abspath(self.resolve(self.config.path)))]

    def _folder(self) -> str:
        return os.path.dirname(os.path.abspath(self.path))


def describe(status: dict[str, Any]) -> str:
    """A status as one line: ``12.0 s, 20400 messages + 1300 for Foxglove's panels = 21700 in the file
    (1700/s), 1.2 MB, 0 dropped, 0 bad``
    (``, 3 files`` once there are several; ``PAUSED: why`` while paused, ``FAILED: why``
    once the recorder has failed)."""
    files = f", {status['files']} files" if status.get("files", 1) > 1 else ""
    unrecorded = f", {status['unrecorded']} unrecorded" if status.get("unrecorded") else ""
    state = (f" — FAILED: {status['failure']}" if status.get("failure") else
             f" — PAUSED: {status['paused']}" if status.get("paused") else "")
    # (the file holds Foxglove's views too: `sonibus info` counts them, so both numbers are said)
    views = (f" + {status['views']} for Foxglove's panels = {status['messages'] + status['views']} in the file"
             if status.get("views") else "")
    return (f"{status['path']}: {status['duration_s']:.1f} s, {status['messages']} messages{views} "
            f"({status['rate']:.0f}/s), {status['bytes'] / 1e6:.1f} MB{files}, {status['dropped']} dropped, "
            f"{status.get('bad', 0)} bad{unrecorded}{state}")
