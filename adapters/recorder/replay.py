"""``replay``: a recording back onto the bus with its original timing, so every
sink works as if the robot were there.

    [nodes.take1]
    adapter = "replay"
    path = "recordings/show.mcap"
    loop = true
    rename = {pepper = "pepper_take1"}     # beside the live pepper

Messages are scheduled against the recording's timeline (never a sleep between
messages), so timing does not drift: each at the time the robot took it (its
``t``, the MCAP publish time), so a frame leaves whole, without the jitter the
live bus added; ``t`` is moved to now and ``seq`` keeps
counting across loops (each audio key's on its own), so sinks' stale-sample
checks, frame reassembly and jitter buffers work unchanged. Audio chunks go
out like the robot's, with the ``AUDIO`` QoS. No wait is longer than ``max_gap_s`` (``timeline.py``): a longer gap
is shortened to it, with a warning. A frame goes out like a robot owner's: the
frame whole on ``<robot>/frame`` (what sinks listen to), then each joint's
sample on its key while anyone subscribes there (``bus/ownership.py``, shared with
live owners); a frame recorded whole (issue 35) as it is, with only the joints
``keys`` selects, a file of before's joint samples of one frame gathered back.
Derived values go out as they were recorded: a derived frame
whole on ``<robot>/derived`` (with only the values ``keys`` selects), or each on
its key (a recording made before derived frames). The replayed robots are owned
like real ones (liveliness, ``<robot>/info`` from the recording) but take no
commands: they answer ``failed``, and ``stop`` ok.
"""

from __future__ import annotations

import itertools
import logging
import os
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from sonibus.bus import codec, commands, framing, keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import CommandError
from sonibus.bus.keys import Key
from sonibus.bus.node import AUDIO, STREAM
from sonibus.bus.options import bad

from .reading import Message, Recording, RecordingError
from .timeline import OFFSETS, Timeline

log = logging.getLogger(__name__)
T = TypeVar("T")

MAX_LATE_S = 0.1  # samples later than this are skipped (events never): no bursts of stale data
LISTENERS_S = 1.0  # after the lead, how long a replay waits for a subscriber before it says nobody listens
LEAD_S = 0.2      # between declaring the publishers and the first message: Zenoh settles its routes
AHEAD = 512       # moments read and decoded ahead of the player (~5 s of a robot at 100 frames/s)
GATHER_NS = 5_000_000  # a frame's joint samples reach a recorder within this of each other
MOMENT = messages.MAX_JOINTS  # joint samples in one moment (a frame's most): what reading ahead holds is bounded
MAX_ROBOTS = 64   # robots one replay claims (each like a live one: a token, two servers; 4,096 took minutes and GBs)
STREAMED = {"joints": STREAM, "derived": STREAM, "audio": AUDIO}  # sections sent as streams (late: skipped)


@dataclass(frozen=True)
class ReplayConfig:
    path: str
    speed: float = 1.0
    loop: bool = False
    start: float = 0.0                  # s from the recording's start
    end: float | None = None            # s from the recording's start; None: to its end
    rename: dict[str, str] = field(default_factory=dict)   # recorded robot → name on the bus
    keys: tuple[str, ...] = ()          # key expressions of what to replay; empty: everything
    max_gap_s: float = 5.0              # the longest wait between two messages (recording time); longer gaps shrink

    def __post_init__(self) -> None:
        if not 0 < self.speed <= 100:
            raise bad("speed", f"{self.speed} must be more than 0 and at most 100")
        if not 0 < self.max_gap_s < float("inf"):
            raise bad("max_gap_s", f"{self.max_gap_s} must be more than 0 (seconds)")
        if self.start < 0:
            raise bad("start", f"{self.start} must be 0 or more")
        if self.end is not None and self.end <= self.start:
            raise bad("end", f"{self.end} must be after start ({self.start})")
        for old, new in self.rename.items():
            try:
                keys.check_name("robot", new)
            except ValueError as exc:
                raise bad("rename", f"{old} → {exc}") from None
        object.__setattr__(self, "keys", keys.patterns(self.keys, "keys") if self.keys else ())


class Replay(Adapter):
    """Replays an MCAP recording onto the bus with its original timing."""

    Config = ReplayConfig
    counters = ("frames", "late", "gaps")

    def __init__(self, config: ReplayConfig, *, name: str = "") -> None:
        super().__init__(config, name=name)
        self.window_s, self.loops = 0.0, 0        # progress: the window's length, passes done
        self.finished = threading.Event()          # set at the end of a replay without loop
        self.problems = ""                         # what the reading skipped (``Recording.problems``), so far
        self._clock: tuple[float, float] | None = None  # the pass's start (monotonic) and the time cut from it
        self.listened = threading.Event()          # set once a node on the bus subscribed to what it replays

    @property
    def position_s(self) -> float:
        """Seconds into the window the replay is now, by its clock: not the last message
        sent, which a gap in the recording or the next pass's start held back (the
        progress line showed 4.8/4.8 s with "loop 2", or stood still through a gap)."""
        if self._clock is None:
            return 0.0
        start, cut_s = self._clock
        return min(self.window_s, max(0.0, (time.monotonic() - start) * self.config.speed + cut_s))

    @classmethod
    def owned_robots(cls, config: ReplayConfig) -> tuple[str, ...]:
        return tuple(config.rename.values())  # the others' names are in the file, known at start

    def _start(self) -> None:
        cfg: ReplayConfig = self.config
        self.recording = self.own(Recording(self.resolve(cfg.path)))
        chosen = self.recording.matching(cfg.keys) if cfg.keys else self.recording.keys
        self.keys = [k for k in chosen if Key.parse(k).section != "cmd"]
        audio = [k for k in self.keys if Key.parse(k).section == "audio"]
        if audio and cfg.speed != 1:  # chunks sent `speed` times as often: every player would overrun
            self.keys = [k for k in self.keys if k not in audio]
            self.warn("audio", f"--speed {cfg.speed:g}: audio left out ({', '.join(audio)}): sound plays only at "
                               "the speed it was recorded")
        robots = sorted({k.partition("/")[0] for k in self.keys})
        if len(robots) > MAX_ROBOTS:
            raise RecordingError(f"{cfg.path} holds {len(robots)} robots ({', '.join(robots[:3])}, ...); a replay "
                                 f"takes at most {MAX_ROBOTS} — choose some with --keys, e.g. --keys '{robots[0]}/**'")
        unknown = sorted(set(cfg.rename) - set(robots))
        if unknown:
            raise RecordingError(f"--as {unknown[0]}: no robot '{unknown[0]}' in {cfg.path} — "
                                 f"it holds {', '.join(robots)}")
        self.names = {robot: cfg.rename.get(robot, robot) for robot in robots}
        self.window_s = min(cfg.end or self.recording.duration_s, self.recording.duration_s) - cfg.start
        if self.window_s < 0:
            raise RecordingError(f"--start {cfg.start:g}: {cfg.path} lasts only {self.recording.duration_s:.1f} s")
        infos = self.recording.infos()
        self._owners = {}  # bus name → its Ownership: the frames go out as a live owner's
        for robot, name in self.names.items():
            self._owners[name] = self.claim_robot(name, f"replay it under another name: --as {robot}={name}_replay")
            if robot in infos:
                self.own(self.bus.serve(keys.info(name), self._info_server(self._info(infos[robot], name))))
            self.own(self.bus.serve(keys.command(name), self._refuse))
        rates = [float(i.get("rate_hz") or 0) for i in infos.values()]
        self._gap_s = 1.0 / max(rates) if rates and max(rates) > 0 else 0.01
        # (derived values recorded in derived frames go out as derived frames, on <robot>/derived)
        framed = {f"{key.partition('/')[0]}/derived" for key in self.keys if Key.parse(key).section == "derived"}
        played = [*self.keys, *(framed & self.recording.derived_frames)]
        self._publishers = {self._renamed(key): self.own(self.bus.stream_publisher(self._renamed(key), qos))
                            for key in played if (qos := STREAMED.get(Key.parse(key).section)) is not None}
        for robot in {k.partition("/")[0] for k in self.keys if Key.parse(k).section == "joints"}:
            self._owners[self.names[robot]].declare_publishers()
        for name in self.names.values():
            self.own(self.bus.watch_subscribers(f"{name}/**", lambda matching: matching and self.listened.set()))
        self.spawn(self._play, "play")
        self.spawn(self._nobody_listens, "listeners")

    def _nobody_listens(self) -> None:
        """Say it once when no node subscribes to what it replays a moment after it starts: Zenoh
        sends nothing then, and a replay with no sink on the bus had said nothing at all."""
        if self.stopping.wait(LEAD_S + LISTENERS_S) or self.listened.is_set():
            return
        names = ", ".join(f"{name}/**" for name in self.names.values())
        self.warn("listeners", f"nobody on the bus subscribes to {names}: the replay goes nowhere — start a sink "
                               "beside it, e.g. an OSC node for your patch (examples/replay-to-patch.toml: "
                               "`sonibus run examples/replay-to-patch.toml`, same bus options as the replay)")

    def _info(self, info: dict[str, Any], name: str) -> dict[str, Any]:
        info = {k: v for k, v in info.items() if k != "connection"}  # (the recorded owner's state: not this one's)
        return {**info, "robot": name, "owner": {"host": self.bus.host, "node": self.name},
                "replay": {"file": os.path.basename(self.config.path), "robot": info.get("robot", name),
                           "speed": self.config.speed}}

    @staticmethod
    def _info_server(info: dict[str, Any]) -> Callable[[zenoh.Query], None]:
        payload, key = codec.encode(info), keys.info(info["robot"])
        return lambda query: query.reply(key, payload, encoding=codec.ENCODING)

    def _refuse(self, query: zenoh.Query) -> None:
        robot, _, verb = str(query.key_expr).partition("/cmd/")
        if verb == "stop":  # (taken, as every stop is; what it did is said: nothing)
            reply = commands.ok_reply(verb, {"held": False, "why": f"'{robot}' is a replay of "
                                             f"{os.path.basename(self.config.path)}: it moves no robot"})
        else:
            reply = commands.error_reply(verb, CommandError(
                "failed", f"'{robot}' is a replay of {os.path.basename(self.config.path)}: it takes no commands"))
        query.reply(query.key_expr, codec.encode(reply), encoding=codec.ENCODING)

    # -- playing ------------------------------------------------------------------

    def _play(self) -> None:
        cfg: ReplayConfig = self.config
        origin_ns = self.recording.start_ns + int(cfg.start * 1e9)
        start: float | None = None
        wall = time.time() - time.monotonic()
        first_seq: dict[str, int] = {}
        last_seq: dict[str, int] = {}
        while not self.stopping.is_set():
            seq_shift = {counter: last_seq[counter] + 1 - first for counter, first in first_seq.items()}
            timeline = Timeline(cfg.max_gap_s)
            ahead = itertools.islice(self.recording.messages(self.keys, cfg.start, cfg.end, frames=True), OFFSETS)
            timeline.prime((m.publish_ns - m.log_ns) / 1e9 for m in ahead)
            if start is None:  # (after the first reading: its time must not make the first messages late)
                start = time.monotonic() + LEAD_S
            self._clock = (start, 0.0)
            reading = self.recording.messages(self.keys, cfg.start, cfg.end, frames=True)
            for framed, moment in ReadAhead(_moments(reading), self.stopping):
                message = moment[0]
                # the robot's timeline (a frame leaves whole), as far as it agrees with the recorder's
                published_s = (message.publish_ns - origin_ns) / 1e9
                at_s = timeline.when(published_s, (message.log_ns - origin_ns) / 1e9)
                offset_s, gap_s = timeline.place(at_s)
                if gap_s:
                    self._gap(gap_s, at_s, message)
                due = start + offset_s / cfg.speed
                if self.stopping.wait(max(0.0, due - time.monotonic())):
                    return
                self._clock = (start, timeline.shift_s)
                if message.key.endswith("/info"):
                    continue
                seq = message.data.get("seq")
                if isinstance(seq, int):
                    counter = _counter(message.key)
                    first_seq.setdefault(counter, seq)
                    seq = last_seq[counter] = seq + seq_shift.get(counter, 0)
                # (a t that strayed is moved with its message: at_s − published_s)
                t_origin = start + wall - (origin_ns / 1e9 + timeline.shift_s - at_s + published_s) / cfg.speed
                late = time.monotonic() - due > MAX_LATE_S
                if framed:
                    self._publish_frame(moment, t_origin, seq, late)
                else:
                    self._publish(message, t_origin, seq, late)
            if self.stopping.is_set():
                return
            self._skipped()
            self.loops += 1
            if not cfg.loop:
                break
            start += (self.window_s - timeline.shift_s + self._gap_s) / cfg.speed
            self._clock = (start, 0.0)
        self.finished.set()
        log.info("%s: replay of %s finished", self.name, cfg.path)

    def _skipped(self) -> None:
        """Say, once a pass, what the reading skipped (a message the gate refuses, a chunk that cannot be
        read); each pass skips the same, so it is said when it changes."""
        problems = self.recording.problems()
        if problems and problems != self.problems:
            self.warn("skipped", problems)
        self.problems = problems

    def _gap(self, gap_s: float, at_s: float, message: Message) -> None:
        self.count("gaps")
        where = f"{at_s - self.config.start:.1f} s into {os.path.basename(self.config.path)} ({message.key})"
        if gap_s > 0:
            self.warn("gap", f"a gap of {gap_s:.1f} s before {where} replayed as {self.config.max_gap_s:g} s "
                             "(max_gap_s, --max-gap)")
        else:
            self.warn("gap", f"time goes back {-gap_s:.1f} s at {where}: replayed on from where it was")

    def _renamed(self, key: str) -> str:
        robot, _, rest = key.partition("/")
        return f"{self.names[robot]}/{rest}"

    def _publish_frame(self, moment: list[Message], t_origin: float, seq: int, late: bool) -> None:
        """One robot's frame (recorded whole, or as its joint samples): the frame whole, then each
        joint's sample on its key."""
        first = moment[0]
        if keys.is_frame(first.key):  # (recorded whole: issue 35)
            data = first.data
            names, values = data["names"], data["v"]
            extra = {q: v for q, v in data.items() if q not in messages.FRAME_FIELDS}
        else:
            values, extra = _join([m.data for m in moment])
            names = [Key.parse(m.key).name for m in moment]
        if late:
            self.count("late", len(names))
            return
        t = self._moved(first.data["t"], t_origin)
        owner = self._owners[self.names[first.key.partition("/")[0]]]
        if owner.publish_frame(framing.frame(t, seq, names, values, extra)):  # per joint too, while wanted
            self.count("frames")
            self.count("sent", len(names))

    def _publish(self, message: Message, t_origin: float, seq: Any, late: bool) -> None:
        key = self._renamed(message.key)
        if not self._owners[key.partition("/")[0]].active:  # another owner keeps this robot name
            return
        data = dict(message.data)
        if isinstance(data.get("t"), int | float):
            data["t"] = self._moved(data["t"], t_origin)
        if seq is not None:
            data["seq"] = seq
        publisher = self._publishers.get(key)
        if publisher is None:  # events: few, and never dropped
            self.bus.put(key, data)
        elif late:
            self.count("late")
            return
        else:
            publisher.put(codec.encode(data))
        self.count("sent")

    def _moved(self, t: float, t_origin: float) -> float:
        """A recorded ``t`` on the replay's clock: now, at its speed."""
        return t_origin + t / self.config.speed


class ReadAhead(Iterator[T]):
    """``items``, taken from a thread of their own up to ``AHEAD`` in advance: reading
    a recording is bursty (a chunk decompressed and decoded at once: milliseconds, and
    hundreds of them on a busy machine), and a burst on the player's thread made every
    message due meanwhile late (at ×2, a third of them skipped). Ends when ``items``
    do or when ``stopping`` is set; an error reading them is raised here, to the player."""

    def __init__(self, items: Iterator[T], stopping: threading.Event, size: int = AHEAD) -> None:
        self._queue: queue.Queue[tuple[bool, Any]] = queue.Queue(size)
        self._stopping = stopping
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._read, args=(items,), name="read-ahead", daemon=True)
        self._thread.start()

    def _read(self, items: Iterator[T]) -> None:
        try:
            for item in items:
                if not self._put((True, item)):
                    return
        except BaseException as exc:  # (a damaged recording: the player fails the node with it)
            self._put((False, exc))
            return
        self._put((False, None))

    def _put(self, entry: tuple[bool, Any]) -> bool:
        while not (self._done.is_set() or self._stopping.is_set()):
            try:
                self._queue.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def __next__(self) -> T:
        while not self._stopping.is_set():
            try:
                more, item = self._queue.get(timeout=0.1)
            except queue.Empty:
                continue
            if more:
                return item
            self.close()
            if item is not None:
                raise item
            break
        self.close()
        raise StopIteration

    def close(self) -> None:
        """Stop reading (the thread ends within 0.1 s; the recording is free again when it has)."""
        self._done.set()
        self._thread.join(1.0)


def _counter(key: str) -> str:
    """Whose ``seq`` a message on ``key`` carries: its robot's frames', or its own audio stream's."""
    parsed = Key.parse(key)
    return key if parsed.section == "audio" else parsed.robot


def _in_frame(message: Message) -> bool:
    """A joint sample with what a frame needs: an integer ``seq``, a number ``t`` and ``v``."""
    data = message.data
    return (Key.parse(message.key).section == "joints" and isinstance(data.get("seq"), int)
            and not isinstance(data["seq"], bool) and messages.number(data.get("t")) and messages.number(data.get("v")))


def _moments(messages: Iterable[Message]) -> Iterator[tuple[bool, list[Message]]]:
    """The messages grouped as they are due: ``(True, [frame])`` for a frame recorded whole,
    ``(True, samples)`` for the joint samples of one robot and one frame (the same ``seq``
    and ``t``, recorded within ``GATHER_NS`` of the first: per-joint recordings, before
    issue 35, interleave robots), ``(False, [message])`` for any other message; in the
    order they were recorded."""
    waiting: deque[tuple[tuple[str, int, float] | bool, list[Message]]] = deque()  # (False: alone; True: a frame)
    gathering: dict[tuple[str, int, float], list[Message]] = {}
    for message in messages:
        while waiting and (waiting[0][0].__class__ is bool or message.log_ns - waiting[0][1][0].log_ns > GATHER_NS):
            frame, moment = waiting.popleft()
            if frame.__class__ is not bool:
                gathering.pop(frame, None)  # type: ignore[arg-type]
            yield frame is not False, moment
        if not _in_frame(message):
            waiting.append((keys.is_frame(message.key), [message]))
            continue
        frame = (message.key.partition("/")[0], message.data["seq"], message.data["t"])
        if frame in gathering and len(gathering[frame]) < MOMENT:
            gathering[frame].append(message)
        else:  # (a moment holds one frame's worth: a file's frame may hold thousands, read ahead by the 512)
            gathering[frame] = [message]
            waiting.append((frame, gathering[frame]))
    for frame, moment in waiting:
        yield frame is not False, moment


def _join(samples: Sequence[dict[str, Any]]) -> tuple[list[float], dict[str, list[float]]]:
    """The positions and extras (those every sample has, as numbers) of one frame's
    joint samples, for ``framing.frame``."""
    shared = [q for q in samples[0]
              if q not in messages.FRAME_FIELDS and all(messages.number(s.get(q)) for s in samples)]
    return [s["v"] for s in samples], {quantity: [s[quantity] for s in samples] for quantity in shared}
