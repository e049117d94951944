"""The ``features`` adapter: joint frames in, derived values and motion events out.

A node is a loop over events: a robot's whole frames (``<robot>/frame``) are
worked out where they arrive, on the subscription's callback thread; one worker
takes the rest from a queue — robots' infos, joint samples reassembled by ``seq``
(``per_joint_keys``), a frame that found the state busy — under the same lock.
Each frame's features are computed and published; ``<robot>/info/derived``
describes what it publishes.

Every derived value of one frame goes out in one message, a derived frame on
``<robot>/derived`` (names ``<feature>/<name>``, as their keys below it); with
``per_key = true`` each goes on its own key ``<robot>/derived/<feature>/<name>``
instead (for scripts that want them so; sinks take either).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import zenoh

from sonibus.bus import codec, framing, keys, lateness
from sonibus.bus.adapter import Adapter
from sonibus.bus.frames import Frame, FrameAssembler
from sonibus.bus.info import InfoRequests
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams, if_free

from . import catalog, table
from .compute import Output, RobotFeatures
from .config import FeaturesConfig

log = logging.getLogger(__name__)

MAX_ROBOTS = 64  # robots whose features are worked out (names made up on the bus must not grow it)
INFO = "\0info"  # queue items carrying a robot's info, so only the worker touches state


class Features(Adapter):
    """Derived movement features: joint velocities, hand positions and speeds, quantity of motion, motion onsets."""

    Config = FeaturesConfig
    counters = ("frames", "events", "late", "missing", "nan", "rejected", "clamped", "not_finite",
                "waiting_info")

    def _start(self) -> None:
        cfg: FeaturesConfig = self.config
        self.robot_features: dict[str, RobotFeatures] = {}  # robot → its features, once its info came
        self._learning: set[str] = set()                    # robots whose info is being worked out
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._assembler = FrameAssembler(cfg.max_wait_ms / 1000.0)  # with per_joint_keys
        self.stats.follow("late", lambda: self._assembler.late)
        self._queue = self.own(SampleQueue(cfg.queue))
        lateness.follow(self.bus)  # (where each robot's node runs: a stale frame's warning names the likely cause)
        self._info = InfoRequests(self.bus, lambda robot, info: self._queue.put((INFO, (robot, info))),
                                  lambda robot, text: self.warn("info", text))
        self._tally = self.stats.tally(("received", "frames", "sent", "events"))  # (counted under self._state)
        # Whole frames are worked out where they arrive (a thread hand-off a frame less: the worker's
        # wake-up cost about what the frame's features do), the rest by the worker from the queue;
        # one lock between them guards the state.
        self._state = threading.Lock()
        self._streams: Streams | None = None  # (a frame may arrive while Streams subscribes: queued, see _direct)
        self._streams = self.own(Streams(self.bus, [keys.joints(r) for r in cfg.robots], self._queue,
                                         per_joint_keys=cfg.per_joint_keys, direct=self._direct))
        self.when_stopping(self._queue.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._run, "features")

    # -- the loop ---------------------------------------------------------------------

    def _run(self) -> None:
        while not self.stopping.is_set():
            expiry = self._assembler.next_expiry()
            # (a joint key's frame waits in the assembler until its expiry; nothing else is timed: a frame
            # is taken where it arrives, the rest comes by the queue, which the stop closes)
            item = self._queue.get(timeout=None if expiry is None else max(0.0, expiry - time.monotonic()))
            with self._state:
                if item is not None:
                    self._take(*item)
                for frame in self._assembler.expire():
                    self.process(frame)

    def _direct(self, key: str, payload: Any) -> bool:
        """A frame, on its subscription's callback thread (``Streams``' ``direct``); into the
        queue instead (False) before it subscribed everywhere or while the worker holds the
        state (``if_free``); left once the node is stopping (its publishers, made after the
        subscriptions, are undeclared before them)."""
        if self.stopping.is_set():
            return True
        return self._streams is not None and if_free(self._state, lambda: self._take(key, payload))

    def _take(self, key: str, payload: Any) -> None:
        if key == INFO:
            self._learn(*payload)
            return
        message = self._streams.take(key, payload, self._counted, self.warn)  # type: ignore[union-attr]
        # (checked by the gate, counted)
        if message is None:
            return
        robot = message.source.robot
        if robot not in self.robot_features:  # (asked only of robots whose data passed the gate)
            self.count("waiting_info")
            self._info.ask(robot)
            return
        if message.source.section == "frame":
            self.process(whole(message))
            return
        for frame in self._assembler.add(robot, key, message.seq, message.t, message.values[0]):
            self.process(frame)

    def _counted(self, kind: str, n: int = 1) -> None:
        """``count``, under ``_state``: what every frame counts goes to the tally."""
        tally = self._tally
        if kind in tally:
            tally[kind] += n
        else:
            self.count(kind, n)

    def process(self, frame: Frame) -> None:
        """Compute and publish the features of one frame."""
        features = self.robot_features[frame.robot]
        max_age = self.config.max_age_ms / 1000.0
        if max_age and time.time() - frame.t > max_age:  # a backlog: what it would give, sinks drop as stale
            self.count("stale")
            self.warn("stale", f"{frame.robot}: frames older than {self.config.max_age_ms:g} ms skipped "
                               f"(frame {frame.seq} was {time.time() - frame.t:.2f} s old: "
                               f"{lateness.why_late(self.bus, frame.robot)})")
            return
        out = features.step(frame.t, frame.seq, frame.values)
        tally = self._tally
        tally["frames"] += 1
        if (out.missing or out.nan) and features.frames > 1:  # the first frame began before the robot's info came
            self.count("missing", out.missing)
            self.count("nan", out.nan)
            self.warn("incomplete", f"{frame.robot}: frame {frame.seq} lacks {out.missing} joint(s) and has "
                                     f"{out.nan} NaN; their velocities are held")
        if out.rejected:
            self.count("rejected", out.rejected)
            self.warn("rejected", f"{frame.robot}: frame {frame.seq}: {out.rejected} joint value(s) refused by the "
                                  f"velocity filter, first {out.refused} (a jump faster than the joint can move, time "
                                  "going back, or not finite); their velocities start over")
        if out.clamped or out.dropped:
            self.count("clamped", out.clamped)
            self.count("not_finite", out.dropped)
            self.warn("clamped", f"{frame.robot}: frame {frame.seq}: {out.clamped} derived value(s) clamped into "
                                 f"their declared ranges, {out.dropped} not finite and left out")
        if self.config.per_key:
            for key, message in out.samples:
                self._publisher(key).put(codec.encode(message))
        elif out.names:
            self._publisher(keys.derived_frame(frame.robot)).put(derived_frame(out))
        tally["sent"] += len(out.names)
        self.record_latency(time.time() - frame.t)
        for key, message in out.events:
            self.bus.put(key, message)
        tally["events"] += len(out.events)

    def _publisher(self, key: str) -> zenoh.Publisher:
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = self._publishers[key] = self.own(self.bus.stream_publisher(key))
        return publisher

    # -- robots -----------------------------------------------------------------------

    def _learn(self, robot: str, info: dict[str, Any]) -> None:
        """Work out ``robot``'s features on a thread of their own: the reach boxes take
        ~0.1 s, and frames queued meanwhile would come out late (and be dropped as stale
        by every sink); until then its frames are skipped as ``waiting_info``."""
        if robot in self.robot_features or robot in self._learning:
            return
        if len(self.robot_features) + len(self._learning) >= MAX_ROBOTS:
            self.capped(f"robot '{robot}': no features, already {MAX_ROBOTS} robots (a thread and a filter each)")
            return
        self._learning.add(robot)
        self.spawn(lambda: self._describe(robot, info), f"learn-{robot}")

    def _describe(self, robot: str, info: dict[str, Any]) -> None:
        cfg: FeaturesConfig = self.config
        try:
            described = table.describe(robot, info)
        except ValueError as exc:
            self.warn("info", f"{robot}: no features: {exc}")
            self._learning.discard(robot)
            return
        if described.arms is None and (cfg.publishes("hand") or cfg.publishes("hand_speed")):
            log.warning("%s: %s: hand positions unavailable: %s", self.name, robot, described.unavailable)
        reply = catalog.derived(described, cfg, {"host": self.bus.host, "node": self.name})
        features = RobotFeatures(described, cfg, catalog.bounds(reply))
        if self.stopping.is_set():
            return
        payload, where = codec.encode(reply), keys.derived_info(robot)
        self.own(self.bus.serve(where, lambda query: query.reply(where, payload, encoding=codec.ENCODING)))
        self.robot_features[robot] = features  # (the worker takes its frames from now on)
        log.info("%s: %s (model '%s'): %d joints, %d derived keys", self.name, robot, described.model,
                 len(described.joints), len(reply["derived"]))


def whole(message: Incoming) -> Frame:
    """The frame of a message taken from ``<robot>/frame``: joint key → position."""
    assert message.selected is not None
    return Frame(message.source.robot, message.seq, message.t,
                 dict(zip([source.key for source in message.selected.sources], message.values, strict=True)))


def derived_frame(out: Output) -> bytes:
    """The message on ``<robot>/derived`` carrying every derived value of a frame, encoded."""
    return codec.encode(framing.derived_frame(out.t, out.seq, out.names, out.values))
