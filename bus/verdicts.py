"""The gate's verdict on a frame, worked out once for every node of a process.

Every node of one ``sonibus run`` that takes a robot's frames decodes and checks the
same payload (the OSC sink, features, the recorder, Foxglove, OSCQuery, the web
node, MIDI: seven times a frame in the show). ``VERDICTS.check(gate, key, payload)``
asks the gate the first time a payload comes and remembers what it said, for the
key, the payload's bytes and the gate's ``Limits`` (equal ones: nodes of one bus share
``Bus.limits``; a node with limits of its own gets a verdict of its own):
the next node given the same bytes on the same key gets the same verdict without
decoding them again.

Each caller gets a message of its own (the map and its lists copied; a copy costs
~1/20 of a check): what one node does with its message (a list changed, a field
added) reaches no other node, nor the remembered one. A refused payload is refused
for each, with the same reason. Only what comes often is remembered (robots' frames
and derived frames, ``Selection.incoming``); events, info and commands are few and
checked by each node. And only while two nodes or more take frames (``join``): a
process of one sink gains nothing by remembering, and would pay for it.

>>> from sonibus.bus.codec import encode
>>> from sonibus.bus.keys import Key
>>> from sonibus.bus.messages import Gate
>>> from sonibus.bus.framing import frame
>>> verdicts, gate = Verdicts(), Gate()
>>> verdicts.join(); verdicts.join()  # (two nodes: what ``Selection`` does)
>>> payload = encode(frame(1.5, 7, ["HeadYaw"], [0.1]))
>>> mine = verdicts.check(gate, Key.parse("pepper/frame"), payload)
>>> mine["v"][0] = 99.0  # (a node's own copy)
>>> verdicts.check(Gate(gate.limits), Key.parse("pepper/frame"), payload), verdicts.checked
({'t': 1.5, 'seq': 7, 'names': ['HeadYaw'], 'v': [0.1]}, 1)
"""

from __future__ import annotations

import threading
from typing import Any

from .capped import Capped
from .keys import Key
from .messages import BadMessage, Gate, Limits

__all__ = ["VERDICTS", "Verdicts"]

MAX_VERDICTS = 256       # payloads remembered (a few frames of each key, for nodes whose queue is behind)
MAX_BYTES = 8 << 20      # about what they hold (a payload of up to 64 KiB, decoded: a few times its size)
PER_BYTE = 4             # what a payload's byte is counted as (itself, and the message decoded from it)
PER_VERDICT = 256        # and each entry beside (its tuple, the key's string)


class Verdicts:
    """Verdicts remembered by key, payload and limits: the message (each caller given a copy)
    or the reason it was refused. Bounded by count and bytes (``Capped``: it starts over past
    either); any thread may call ``check``."""

    def __init__(self, items: int = MAX_VERDICTS, size: int = MAX_BYTES) -> None:
        # (key, payload) → (the limits, the message or the reason refused): nodes with other limits
        # than the last one's check again (and are remembered in its place)
        self._table: Capped[tuple[str, bytes], tuple[Limits, tuple[dict[str, Any], Any] | str]] = Capped(items, size)
        self._lock = threading.Lock()  # (gets are dict lookups; puts count bytes and may clear)
        self.checked = 0  # payloads the gate was asked about (the others were remembered)
        self.takers = 0  # what takes frames in this process (``join``, ``leave``): remembered only if two or more

    def join(self) -> None:
        """One more taker of frames (a ``Selection``); ``leave`` when it is gone."""
        with self._lock:
            self.takers += 1

    def leave(self) -> None:
        with self._lock:
            self.takers -= 1
            if self.takers < 2:
                self._table.clear()

    def check(self, gate: Gate, key: Key, payload: bytes, nested: bool = False) -> dict[str, Any]:
        """``gate.check(key, payload)``, or what it said of the same bytes on ``key`` with the
        same limits before: a message of the caller's own, or ``BadMessage``. ``nested``: the
        message's ``v`` may hold lists (a derived frame's), copied too."""
        return self.verdict(gate, key, payload, nested)[0]

    def verdict(self, gate: Gate, key: Key, payload: bytes,
                nested: bool = False) -> tuple[dict[str, Any], tuple[str, ...] | None]:
        """``check``, with what the gate found beside the message (``Gate.verdict``: a frame's
        names, an immutable tuple shared by every caller)."""
        limits = gate.limits
        if self.takers < 2 or payload.__class__ is not bytes:  # (alone: nobody to share with; an oversize
            return gate.verdict(key, payload)  # marker: refused by the gate at once)
        entry = (key.key, payload)
        found = self._table.get(entry)
        if found is None or (found[0] is not limits and found[0] != limits):  # (one bus's nodes: the same object)
            try:
                verdict: tuple[dict[str, Any], tuple[str, ...] | None] | str = gate.verdict(key, payload)
            except BadMessage as exc:
                verdict = str(exc)
            found = (limits, verdict)
            with self._lock:
                self.checked += 1
                self._table.put(entry, found, PER_BYTE * len(payload) + PER_VERDICT)
        verdict = found[1]
        if verdict.__class__ is str:
            raise BadMessage(verdict)
        return own(verdict[0], nested), verdict[1]  # type: ignore[index]

    def __len__(self) -> int:
        return len(self._table)

    def __repr__(self) -> str:
        return f"<Verdicts {len(self._table)} remembered, {self.checked} checked>"


def own(message: dict[str, Any], nested: bool = False) -> dict[str, Any]:
    """A copy of a checked frame's (or derived frame's) message that shares nothing mutable
    with it: the map, its lists and (``nested``) the lists in its ``v``. A checked frame holds
    numbers and strings in lists one deep (the gate refuses anything else), a derived frame's
    ``v`` lists of numbers besides."""
    out = message.copy()
    if not nested and len(out) == 4:  # (the usual frame: t, seq, names, v; no call a field)
        out["names"], out["v"] = out["names"].copy(), out["v"].copy()
        return out
    for field, value in out.items():  # (values replaced, none added: iterating stays valid)
        if value.__class__ is list:
            out[field] = [x.copy() if x.__class__ is list else x for x in value] if nested and field == "v" \
                else value.copy()
    return out


VERDICTS = Verdicts()
"""The process's: every ``Selection`` (every sink of every node) checks frames through it."""
