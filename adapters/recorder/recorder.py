"""``recorder``: everything on the bus (or what ``subscribe`` selects) into an
MCAP file, beside a live installation and without slowing it down.

    [nodes.logger]
    adapter = "recorder"
    path = "recordings/show-{time}.mcap"      # {time}: when it starts, 20261122-140501

Joints come as frames (``<robot>/frame``, one Zenoh sample per frame; see
``bus/streams.py``) and are written as the samples of their joint keys, so a
file is the same as if each joint key had been recorded; ``per_joint_keys =
true`` records joint keys as published instead (publishers that put no frames).

Unless ``foxglove = false`` it also writes the views Foxglove's panels read
(``adapters/foxglove/views.py``): ``<robot>/frame`` (each frame whole), ``<robot>/log``
(events as ``foxglove.Log``), ``<robot>/tf`` (the arms as
``foxglove.FrameTransforms``, every frame, once the robot's info names a model
with kinematics) and ``<robot>/info/derived`` (what feature processors answer
there: the derived keys' units and ranges). They are counted in ``foxglove``,
not ``written``; readers of bus data (replay, export, plot) leave them out.

Audio (``<robot>/audio/mic``, ``<robot>/audio/speaker``) is recorded by default
too, a channel per key holding each chunk as msgpack (``channels.encoding_of``);
``sonibus export --wav`` makes WAV files of them (``wav.py``).

Messages wait in the recorder's own bounded queue; if the disk cannot keep up
the oldest are dropped and counted (``stats["dropped"]``), never silently. A
message the gate or the writer refuses is counted in ``bad`` and skipped; a
writer that fails (disk full) fails the node (``Adapter.fail``), and the file
is closed as far as it got. A ``path`` that cannot be written is a
``ConfigError`` when the node is configured or, at the latest, started.
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from dataclasses import dataclass
from typing import Any

from sonibus.adapters.foxglove.views import DERIVED_INFO, Views, joint_samples
from sonibus.bus import codec, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import ConfigError
from sonibus.bus.info import InfoRequests
from sonibus.bus.options import bad
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

from .writer import BadRecord, RecordingWriter, WriteError, unwritable

log = logging.getLogger(__name__)

EVERYTHING = ("*/joints/*", "*/derived/**", "*/events/*", "*/audio/*")


@dataclass(frozen=True)
class RecorderConfig:
    path: str
    subscribe: tuple[str, ...] = EVERYTHING   # robot info is always recorded, once per robot
    overwrite: bool = False
    queue: int = 1 << 16                      # messages waiting for the disk (a frame is one: minutes of two robots)
    flush_s: float = 1.0                      # at most this much is lost if the recorder is killed
    status_every_s: float = 10.0              # a log line with what has been recorded; 0: none
    per_joint_keys: bool = False              # joints from <robot>/joints/* instead of <robot>/frame (bus/streams.py)
    foxglove: bool = True                     # also the views Foxglove reads: <robot>/frame, /log, /tf, /info/derived

    def __post_init__(self) -> None:
        if not self.path:
            raise bad("path", "is empty — name the .mcap file to write")
        object.__setattr__(self, "subscribe", keys.patterns(self.subscribe))
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        if not self.flush_s > 0:
            raise bad("flush_s", f"{self.flush_s} must be more than 0")
        problem = unwritable(self.resolved_path())
        if problem:
            raise bad("path", problem)

    def resolved_path(self, now: float | None = None) -> str:
        return self.path.replace("{time}", time.strftime("%Y%m%d-%H%M%S", time.localtime(now)))


class Recorder(Adapter):
    """Records joints, derived values, events, audio and robot info into an MCAP file."""

    Config = RecorderConfig
    counters = ("written",)

    def _start(self) -> None:
        cfg: RecorderConfig = self.config
        self.path = cfg.resolved_path()
        if os.path.exists(self.path) and not cfg.overwrite:
            raise ConfigError(f"{self.path} exists — choose another name, or overwrite it (--force, overwrite = true)")
        self._wall0, self._mono0 = time.time_ns(), time.monotonic_ns()
        self._writer = self._open({"host": self.bus.host, "node": self.name, "subscribe": " ".join(cfg.subscribe),
                                   "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
        self._queue = self.own(SampleQueue(cfg.queue))
        self._info_seen: set[str] = set()
        self._views = Views(self.bus, self._take_derived_info) if cfg.foxglove else None
        self._info = InfoRequests(self.bus, self._take_info, lambda robot, text: log.warning("%s", text))
        try:
            self._streams = Streams(self.bus, cfg.subscribe, self._queue, per_joint_keys=cfg.per_joint_keys,
                                    stamped=True, pace=False)  # a recording keeps every frame, bursts too
        except BaseException:
            self._writer.close()
            raise
        self._last_status = time.monotonic()
        self.spawn(self._write, "write")

    def _open(self, metadata: dict[str, str]) -> RecordingWriter:
        """The writer of ``self.path`` (its folders created); a path that cannot be
        written is a configuration error, found here at start rather than at the first chunk."""
        try:
            directory = os.path.dirname(self.path)
            if directory:
                os.makedirs(directory, exist_ok=True)
            return RecordingWriter(self.path, metadata, flush_s=self.config.flush_s)
        except (OSError, WriteError) as exc:
            reason = exc if isinstance(exc, WriteError) else f"cannot write {self.path}: {exc.strerror or exc}"
            raise ConfigError(f"node '{self.name}': key 'path': {reason} — "
                              "choose a folder that exists or can be created, and that you can write to") from None

    def _stop(self) -> None:
        if hasattr(self, "_streams"):  # first, so the writer drains all that came
            self._streams.undeclare()

    def status(self) -> dict[str, Any]:
        """What has been recorded so far."""
        elapsed = (time.monotonic_ns() - self._mono0) / 1e9
        return {"path": self.path, "duration_s": elapsed, "messages": self.stats["written"],
                "rate": self.stats["written"] / elapsed if elapsed > 0 else 0.0,
                "bytes": self._writer.size, "dropped": self._queue.dropped, "bad": self.stats["bad"],
                "failure": self.failure}

    def metrics(self) -> dict[str, Any]:
        """The file and its size so far."""
        writer = getattr(self, "_writer", None)
        return {"path": self.path, "bytes": writer.size} if writer is not None else {}

    def _take_info(self, robot: str, info: dict[str, Any]) -> None:  # on a Zenoh thread
        self._queue.put((keys.info(robot), codec.encode(info), time.monotonic_ns()))

    def _take_derived_info(self, key: str, payload: bytes) -> None:  # on a Zenoh thread
        self._queue.put((key, payload, time.monotonic_ns()))

    def _write(self) -> None:
        try:
            while not self.stopping.is_set():
                for item in self._queue.drain(timeout=0.2):
                    self._record(*item)
                self._report()
            while (item := self._queue.get(timeout=0)) is not None:  # what arrived before stop
                self._record(*item)
        except BaseException:
            # Raised again for the base class to fail the node loudly. The file is finished if it
            # is sound, else only closed: recover then keeps its complete chunks.
            with contextlib.suppress(WriteError):
                self._writer.close(dict(self.stats))
            raise
        self._writer.close(dict(self.stats))
        log.info("%s: %s", self.name, describe(self.status()))

    def _record(self, key: str, payload: bytes, arrived_ns: int) -> None:
        log_ns = self._wall0 + arrived_ns - self._mono0
        if self._views is not None and key.endswith("/" + DERIVED_INFO):  # (an answer the views asked for)
            self._derived_info(self._views, key, payload, log_ns)
            return
        incoming = self._streams.take(key, payload, self.count, self.warn)  # checked by the gate, counted
        if incoming is None:
            return
        samples = joint_samples(incoming) if incoming.source.section == "frame" else [(key, incoming.message)]
        robot = key.partition("/")[0]
        if key.endswith("/info"):
            if robot in self._info_seen:
                return
            self._info_seen.add(robot)
        elif robot not in self._info_seen:
            self._info.ask(robot)
        for sample_key, sample in samples:
            if self._put(sample_key, log_ns, sample):
                self.count("written")
        if self._views is not None:
            views = self._views.of(incoming)
            self.count("foxglove", sum(self._put(view, log_ns, message) for view, message in views))

    def _put(self, key: str, log_ns: int, message: dict[str, Any]) -> bool:
        """Write one message; one the writer refuses is counted ``bad`` and skipped."""
        try:
            self._writer.write(key, log_ns, message)
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
        if self._put(key, log_ns, message):
            self.count("foxglove")

    def _report(self) -> None:
        every = self.config.status_every_s
        if every and time.monotonic() - self._last_status >= every:
            self._last_status = time.monotonic()
            log.info("%s: %s", self.name, describe(self.status()))


def describe(status: dict[str, Any]) -> str:
    """A status as one line: ``12.0 s, 20400 messages (1700/s), 1.2 MB, 0 dropped, 0 bad``
    (and ``FAILED: why`` once the recorder has failed)."""
    failure = f" — FAILED: {status['failure']}" if status.get("failure") else ""
    return (f"{status['path']}: {status['duration_s']:.1f} s, {status['messages']} messages "
            f"({status['rate']:.0f}/s), {status['bytes'] / 1e6:.1f} MB, {status['dropped']} dropped, "
            f"{status.get('bad', 0)} bad{failure}")
