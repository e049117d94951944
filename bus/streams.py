"""What a sink subscribes to for the keys it asks for.

A robot owner publishes each frame twice: a sample per joint on
``<robot>/joints/<Joint>`` (for anyone) and the whole frame once on
``<robot>/frame``. A sink that asks for joint keys (``*/joints/*``,
``pepper/joints/R*``) is served from the frames of the robots its patterns
name, and lets through the joints the patterns select: one Zenoh sample per
frame reaches its process instead of one per joint (docs/performance.md).
Publishers that put joint keys only (a script of your own) need
``per_joint_keys = true``.

Audio (``<robot>/audio/...``) comes only with a pattern that names its section
(``pepper/audio/mic``, ``*/audio/*``): ``pepper/**`` brings none, and does not
even subscribe to it — it is narrowed to the sections it may take (``narrowed``),
so a robot's microphones, published only while someone subscribes, stay off for
an OSC sink of ``pepper/**``. A sink that cannot carry audio refuses a pattern
naming audio in its configuration (``without_audio``).

Derived values travel the same way: a feature processor publishes every value of
one frame in one message on ``<robot>/derived`` (``derived``), and a pattern that
selects derived keys (``*/derived/**``, ``pepper/derived/qom/*``) is served from it
too; what it selects comes out as the samples its keys would carry (``Incoming.parts``,
made once here for every sink). Per-key derived samples (a processor with
``per_key = true``, a map node, a script) still come on their own keys.

``bus/plan.py`` works out the key expressions; this module takes what comes of them.
"""

from __future__ import annotations

import logging
import operator
import threading
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, NamedTuple

import zenoh
from msgpack import unpackb

from . import keys, messages
from .capped import PER_NAME, Capped, size_of
from .node import Bus
from .pacing import Spacing
from .plan import frame_keys_of, from_frames_of, narrowness, plan, skipping
from .queue import SampleQueue
from .verdicts import VERDICTS

log = logging.getLogger(__name__)

MAX_KEYS = 10_000  # keys taken apart and remembered
MAX_FRAMES = 1024  # joint lists of frames remembered (their selection)
MAX_BYTES = 2 << 20  # of names in each of those tables (a frame's 128 names may fill its 64 KB: a count is no cap)
_PARSED = 400      # bytes of a parsed key beside its characters (the ``Key`` and its four strings)


class Selected(NamedTuple):
    """The joints a sink's patterns take out of one robot's frames with one joint list:
    their ``sources``, at ``indices`` in the frame (None: all of them, in order), and
    their ``keys``. Made once per joint list and kept: a sink may key what it works out
    for these frames by its identity."""

    sources: tuple[keys.Key, ...]
    indices: tuple[int, ...] | None
    keys: frozenset[str]


class Incoming(NamedTuple):
    """A checked message as a sink takes it: an event (``event`` set), a sample
    (``t``, ``seq``, ``values``) or a frame (``t``, ``seq``, the joints a sink's
    patterns select in ``selected`` and their ``values``, in that order); ``message``
    is the payload, decoded."""

    source: keys.Key
    message: dict[str, Any]
    event: dict[str, Any] | None = None
    t: float = 0.0
    seq: int = 0
    values: tuple[float, ...] = ()
    selected: Selected | None = None
    parts: Parts | None = None  # a derived frame's selected values, as their keys' samples (made when looked at)

    @property
    def samples(self) -> tuple[Incoming, ...]:
        """A frame's selected joints, each as a sample (made at each call: a sink that
        takes many frames reads ``selected`` and ``values`` instead)."""
        if self.selected is None:
            return ()
        message, t, seq = self.message, self.t, self.seq
        return tuple(Incoming(source, message, None, t, seq, (value,))
                     for source, value in zip(self.selected.sources, self.values, strict=True))

    @property
    def joints(self) -> Sequence[Incoming]:
        """The samples it carries: a frame's, a derived frame's (``parts``), or itself."""
        if self.parts is not None:
            return self.parts
        return self.samples if self.selected is not None else (self,)


_new = tuple.__new__  # (an ``Incoming`` made from all its fields at once: ``incoming``)
_Chosen = tuple[tuple[str, ...], Selected, Callable[[list[Any]], tuple[Any, ...]]]  # names, selection, picker


def _picker(indices: tuple[int, ...] | None) -> Callable[[list[Any]], tuple[Any, ...]]:
    """What takes the values at ``indices`` (None: all) out of a frame's ``v``, as a tuple, in C."""
    if indices is None:
        return tuple
    if len(indices) == 1:
        return lambda values, i=indices[0]: (values[i],)
    if not indices:
        return lambda values: ()
    return operator.itemgetter(*indices)


class Parts(Sequence[Incoming]):
    """A derived frame's selected values as the samples of their own keys (``Incoming.parts``),
    made the first time a sink looks at them: a node that takes derived frames whole (the
    recorder) never pays for them. Its length is known without them; ``sources`` (their keys,
    the same tuple for every frame of the robot with the same names: a sink may key what it
    works out for them by its identity) and ``values`` (as the frame carries them: a number,
    or a list of numbers, each) are there without them too (the OSC sink sends from them)."""

    __slots__ = ("_made", "seq", "sources", "t", "values")

    def __init__(self, sources: tuple[keys.Key, ...], values: tuple[Any, ...], t: float, seq: int) -> None:
        self.sources, self.values, self.t, self.seq = sources, values, t, seq
        self._made: tuple[Incoming, ...] | None = None

    def _parts(self) -> tuple[Incoming, ...]:
        made = self._made
        if made is None:  # (two threads may both make them: equal tuples, either kept)
            t, seq = self.t, self.seq
            # (a list made in one comprehension, each part made as a tuple: no generator to resume, no
            # NamedTuple __new__ to call, 26 times a frame for each node that takes derived values)
            made = self._made = tuple([_new(Incoming, (
                key, {"t": t, "seq": seq, "v": value}, None, t, seq,
                tuple(map(float, value)) if value.__class__ is list else (float(value),), None, None))
                for key, value in zip(self.sources, self.values, strict=True)])
        return made

    def __len__(self) -> int:
        return len(self.sources)

    def __bool__(self) -> bool:
        return bool(self.sources)

    def __iter__(self) -> Iterator[Incoming]:
        return iter(self._parts())

    def __getitem__(self, index: Any) -> Any:
        return self._parts()[index]

    def __eq__(self, other: object) -> bool:
        return self._parts() == (other._parts() if isinstance(other, Parts) else other)

    def __hash__(self) -> int:
        return hash(self._parts())

    def __repr__(self) -> str:
        return repr(self._parts())


class Selection:
    """What a sink's ``patterns`` select, and what it receives, checked by the
    message layer's gate: ``incoming``/``take`` decode, ``accepts(key)`` tells
    whether a joint of a frame is one the patterns select (what a robot's frames
    with one joint list give is worked out once: ``selected``).

    >>> from sonibus.bus import framing
    >>> from sonibus.bus.codec import encode
    >>> selection = Selection(["pepper/joints/Head*"])
    >>> frame = framing.frame(1.5, 7, ["HeadYaw", "LHand"], [0.1, 0.9])
    >>> [s.source.name for s in selection.incoming("pepper/frame", encode(frame)).samples]
    ['HeadYaw']
    """

    def __init__(self, patterns: Iterable[str], limits: messages.Limits | None = None) -> None:
        self.gate = messages.Gate(limits)
        VERDICTS.join()  # (the frames this takes are checked once for the process: bus/verdicts.py)
        weakref.finalize(self, VERDICTS.leave)
        self._selected = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]
        # (keys, robots and joint names come from the network: every table is capped, count and bytes)
        self._accepted: Capped[str, bool] = Capped(MAX_KEYS, MAX_BYTES)
        self._parsed: Capped[str, keys.Key] = Capped(MAX_KEYS, MAX_BYTES)
        self._frames: Capped[tuple[str, tuple[str, ...]], Selected] = Capped(MAX_FRAMES, MAX_BYTES)
        self._last: Capped[str, _Chosen] = Capped(MAX_FRAMES, MAX_BYTES)  # robot → its last names' snapshot

    def incoming(self, key: str, payload: bytes) -> Incoming:
        """What came on ``key``, checked by the gate (a frame keeps the selected joints);
        ``messages.BadMessage`` saying what is wrong otherwise."""
        source = self._parsed.get(key) or self._key(key)  # (the usual: a key parsed before, no call)
        section = messages.SECTIONS.get(source.section)
        taken_as = section.taken_as if section is not None else ""
        derived = source.section == "derived" and not source.name  # <robot>/derived: a derived frame
        if (taken_as == "frame" or derived) and VERDICTS.takers > 1:  # (the process's other nodes take the
            # same bytes: checked once for them all, each given a message of its own; bus/verdicts.py)
            message, names = VERDICTS.verdict(self.gate, source, payload, nested=derived)
        else:
            message, names = self.gate.verdict(source, payload)  # (a key of no section is refused here)
        if taken_as == "frame":
            # (the gate compared the names with the robot's last frame's and gave the same tuple if they
            # were: the selection for them is found by identity, no name compared again; one snapshot
            # read once, so two threads taking frames of one robot never mix two selections)
            chosen = self._last.get(source.robot)
            if chosen is None or chosen[0] is not names:
                chosen = self._chosen(source.robot, names or tuple(message["names"]))
            values = chosen[2](message["v"])
            if names is None:  # (not all floats: ints, which the gate let through)
                values = tuple(map(float, values))
            # (made as a tuple: no NamedTuple __new__ to call, every frame of every node; issue 35)
            return _new(Incoming, (source, message, None, message["t"], message["seq"], values, chosen[1], None))
        if derived:
            return self._derived_frame(source, message, names)
        if taken_as == "sample":
            value = message["v"]
            values = tuple(map(float, value)) if isinstance(value, list) else (float(value),)
            return Incoming(source, message, None, message["t"], message["seq"], values)
        return Incoming(source, message, message)

    def _steady(self, key: str, payload: bytes) -> Incoming | None:
        """``incoming`` of a robot's frame with the names of the last one it selected from, in one
        pass: read from its bytes as the last one's (``Gate.known_frame``: the usual), or decoded
        and checked by the gate's ``frame`` (the check ``incoming`` makes of it), then selected by
        the snapshot kept for those names. None for anything else, and for a frame the gate
        refuses, whatever it is: ``incoming`` takes it then, and says why (a frame refused is
        decoded twice, and refused the same way: what the gate noted of its names before it
        refused it, it notes again).

        An OSC bundle frame of 17 joints: 72k instructions, against 90k by ``incoming``'s way
        (msgpack's strings and floats, the names compared, the types looked at, four calls and
        their lookups; docs/performance.md, "The frame lane", issue 35)."""
        source = self._parsed.get(key)
        if source is None or source.section != "frame" or VERDICTS.takers > 1 \
                or not 0 < len(payload) <= self.gate.limits.max_payload:
            return None  # (another key; or the process's other nodes share the verdicts: bus/verdicts.py)
        chosen = self._last.get(source.robot)
        if chosen is None:
            return None
        known = self.gate.known_frame(source, payload)  # (its bytes read as the last frame's: the usual)
        if known is not None:
            t, seq, values, names = known
            if names is not chosen[0]:
                return None
            # (a message of its own, as msgpack would have made it: a node may change it, or keep it)
            return _new(Incoming, (source, {"t": t, "seq": seq, "names": list(names), "v": list(values)}, None, t,
                                   seq, chosen[2](values), chosen[1], None))
        try:
            message = unpackb(payload, raw=False, strict_map_key=False)
            if message.__class__ is not dict or self.gate.frame(source, message) is not chosen[0]:
                return None  # (other names: worked out by incoming, and the snapshot's then)
            return _new(Incoming, (source, message, None, message["t"], message["seq"], chosen[2](message["v"]),
                                   chosen[1], None))
        except Exception:  # (whatever is wrong with it: incoming says what)
            return None

    def _derived_frame(self, source: keys.Key, message: dict[str, Any], names: tuple[str, ...] | None) -> Incoming:
        """A derived frame, with the values the patterns select as the samples of their own keys
        (made when a sink first looks at them: ``Parts``)."""
        chosen = self._last.get(source.key)
        if chosen is None or chosen[0] is not names:
            chosen = self._chosen(source.key, names or tuple(message["names"]), source.key + "/")
        t, seq = message["t"], message["seq"]
        parts = Parts(chosen[1].sources, chosen[2](message["v"]), t, seq)
        return _new(Incoming, (source, message, None, t, seq, (), None, parts))  # (as a frame's: no __new__ call)

    def selected(self, robot: str, names: list[str] | tuple[str, ...], prefix: str = "") -> Selected:
        """The joints of ``robot``'s frames with ``names`` (checked by the gate) that the patterns select
        (``prefix``: their keys' beside the names, ``<robot>/joints/`` unless given; a derived frame's
        are ``<robot>/derived/``, and ``robot`` is then its key)."""
        return self._chosen(robot, names if names.__class__ is tuple else tuple(names), prefix)[1]

    def _chosen(self, robot: str, names: tuple[str, ...], prefix: str = "") -> _Chosen:
        """``robot``'s snapshot for frames with ``names``: the names, their ``Selected`` and what picks
        the selected values out of a frame's ``v``, kept as the robot's last (``incoming`` finds it
        by the identity of the gate's names)."""
        size = size_of(names) + len(robot)
        last = self._last.get(robot)
        if last is not None and last[0] == names:  # (the same names, another tuple: kept with this one)
            return self._last.put(robot, (names, last[1], last[2]), size)
        signature = (robot, names)
        found = self._frames.get(signature)
        if found is None:
            prefix = prefix or f"{robot}/joints/"
            indices = tuple(i for i, name in enumerate(names) if self.accepts(prefix + name))
            sources = tuple(self._key(prefix + names[i]) for i in indices)
            found = self._frames.put(signature, Selected(sources, None if len(indices) == len(names) else indices,
                                                         frozenset(source.key for source in sources)),
                                     size + PER_NAME * len(indices))  # (its keys, mostly _parsed's)
        return self._last.put(robot, (names, found, _picker(found.indices)), size)

    def take(self, key: str, payload: bytes, count: Callable[[str, int], None],
             warn: Callable[[str, str], None]) -> Incoming | None:
        """``incoming``, counted by a sink's ``count`` (``Adapter.count``: ``received``, a
        frame as its samples; ``bad``); a bad message is ``warn``ed about (naming the key
        and the reason) and gives None."""
        try:
            message = self.incoming(key, payload)
        except ValueError as exc:  # messages.BadMessage, or a key that is not a data key
            count("received", 1)
            count("bad", 1)
            warn("bad", f"message on '{key}' refused: {exc}")
            return None
        if message.parts is not None:
            count("received", len(message.parts) or 1)
        else:
            count("received", (len(message.values) if message.selected is not None else 0) or 1)
        return message

    def accepts(self, key: str) -> bool:
        """Whether joint ``key`` (taken from a frame) is one the patterns select."""
        accepted = self._accepted.get(key)
        if accepted is None:
            accepted = self._accepted.put(key, any(p.intersects(key) for p in self._selected), len(key) + PER_NAME)
        return accepted

    def _key(self, key: str) -> keys.Key:
        parsed = self._parsed.get(key)
        if parsed is None:
            parsed = self._parsed.put(key, keys.Key.parse(key), 2 * len(key) + _PARSED)
        return parsed


class Held(NamedTuple):
    """A message ``Streams`` held back for its turn (``bus/pacing.py``), as the queue
    gives it back in place of its payload."""

    message: Incoming


class Streams(Selection):
    """The subscriptions of ``patterns`` into ``queue`` (see ``plan``), and their ``Selection``.

    Skip, never burst (``pace``, on unless a sink must keep every frame, as the recorder):
    frames and samples of one key that arrive faster than their own rate — the backlog of
    a stalled link or process — never go out as a burst: after a stall they are spaced
    by ``pacing.Spacing``. One goes, the newest of the rest waits in ``queue`` for its
    turn, the others are skipped and counted (``skipped``). ``max_age_ms`` and the like
    only drop what is old; this keeps what is young from arriving all at once.

    ``direct``: a sink that takes frames where they arrive (on the subscription's callback
    thread, guarding its state with a lock of its own) is given each frame there (a robot's
    ``<robot>/frame`` and a derived frame, ``<robot>/derived``), as
    ``direct(key, payload)``, instead of through ``queue`` (what it returns False for goes
    into ``queue``); everything else still comes through ``queue``. It saves a thread
    hand-off per frame (docs/performance.md, "The queue hop"), but a sink that falls
    behind there holds up the Zenoh session's callbacks: only for what is quick."""

    def __init__(self, bus: Bus, patterns: Iterable[str], queue: SampleQueue, *,
                 per_joint_keys: bool = False, stamped: bool = False, limits: messages.Limits | None = None,
                 pace: bool = True, direct: Callable[[str, Any], bool] | None = None) -> None:
        super().__init__(patterns := tuple(patterns), limits or bus.limits)
        if pace and stamped:
            raise ValueError("stamped items cannot be paced: a held item would lose its stamp")
        self.queue = queue
        self.plan = plan(patterns, per_joint_keys)
        self.spacing = Spacing() if pace else None
        self._held: dict[str, Held] = {}  # key → the message waiting for its turn in the queue
        self._held_lock = threading.Lock()
        if self.plan.frames:  # said once: what a user asked for is not the key subscribed to
            log.info("%s: %s served from whole frames on %s (per_joint_keys = true for publishers of "
                     "joint keys only)", bus.node, ", ".join(patterns), ", ".join(self.plan.frames))
        # (derived frames as the robot's: one a tick beside it, as quick to take; through the queue, the
        # worker's wake-up cost an OSC sink more than the frame's work: docs/performance.md)
        subscriptions = [(k, {"queue": queue, "direct": direct}) for k in (*self.plan.frames, *self.plan.derived)]
        subscriptions += [(k, {"queue": queue, "skip": skipping(k, frame_keys_of(k))}) for k in self.plan.keys]
        subscriptions += [(k, {"queue": queue, "skip": skipping(k, from_frames_of(k))}) for k in self.plan.broad]
        # (the broadest first: one of them that includes another serves it too, bus/fanout.py)
        subscriptions.sort(key=lambda subscription: narrowness(subscription[0]))
        self.subscribers = [bus.subscribe(k, stamped=stamped, **options)[0] for k, options in subscriptions]

    def take(self, key: str, payload: bytes | Held, count: Callable[[str, int], None],
             warn: Callable[[str, str], None], now: float | None = None) -> Incoming | None:
        """``Selection.take``, then the pacing: None for a message held for its turn
        (the queue gives it back then, as a ``Held``) or skipped (counted). ``now``: the
        caller's ``time.monotonic()``, if it has one (the pacing reads the clock otherwise)."""
        if payload.__class__ is bytes:
            message = self._steady(key, payload)
            if message is not None:  # (a frame like the robot's last: checked and selected in one pass)
                count("received", len(message.values) or 1)
                if self.spacing is None:
                    return message
                return self._paced(key, message, count, now, True)
        if payload.__class__ is Held:
            with self._held_lock:
                newest = self._held.get(key) is payload
                if newest:
                    del self._held[key]
            if not newest:  # (replaced while the queue gave it out: counted then)
                return None
            message = payload.message  # type: ignore[union-attr]
        else:
            message = super().take(key, payload, count, warn)  # type: ignore[arg-type]
            if message is None or self.spacing is None or message.event is not None:
                return message
        return self._paced(key, message, count, now, payload.__class__ is not Held)

    def _paced(self, key: str, message: Incoming, count: Callable[[str, int], None], now: float | None,
               arrived: bool) -> Incoming | None:
        """``message`` if its turn is now; else held for it (the queue gives it back then) or
        skipped (counted), and None. ``arrived``: False for a held one whose turn came."""
        turn = self.spacing.turn(key, message.t, message.seq, now, arrived)  # type: ignore[union-attr]
        if turn.go:
            return message
        if not turn.until:
            count("skipped", 1)
            return None
        held = Held(message)
        with self._held_lock:
            replaced = self._held.pop(key, None)
            if replaced is None and len(self._held) >= self.queue.maxlen:  # (keys come from the network)
                del self._held[next(iter(self._held))]  # the one the queue drops too (held longest), counted there
            self._held[key] = held
        self.queue.hold(key, (key, held), turn.until)
        if replaced is not None:
            count("skipped", 1)
        return None

    def each(self, stopping: threading.Event, count: Callable[[str, int], None],
             warn: Callable[[str, str], None]) -> Iterator[Incoming]:
        """The checked messages of the queue (see ``take``) until ``stopping`` is set:
        the loop of a node's worker. It waits for a message (or a held one's turn), not for
        time: the node closes the queue at its stop (``Adapter.when_stopping(queue.close)``)."""
        while not stopping.is_set():
            item = self.queue.get()
            message = self.take(item[0], item[1], count, warn) if item else None
            if message is not None:
                yield message

    def undeclare(self) -> None:
        for subscriber in self.subscribers:
            subscriber.undeclare()
        self.subscribers.clear()


def if_free(lock: threading.Lock, take: Callable[[], None]) -> bool:
    """``take()`` holding ``lock`` if nobody holds it now (True); else nothing (False). What a
    sink's ``direct`` does: Zenoh's callback threads serve every subscription and query of the
    session and must never wait on a sink (a batch of thousands of fuzzed samples held them
    for seconds), so while its worker holds the sink's state the frame goes to its queue."""
    if not lock.acquire(blocking=False):
        return False
    try:
        take()
    finally:
        lock.release()
    return True
