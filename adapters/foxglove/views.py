"""The views of the bus that Foxglove's panels read, beside the bus's own keys:
per robot, each frame whole (``<robot>/frame``), its events as ``foxglove.Log``
(``<robot>/log``), its arms as ``foxglove.FrameTransforms`` (``<robot>/tf``)
and its processors' ``<robot>/info/derived``. The recorder writes them, the
``foxglove`` adapter serves them; neither needs foxglove-sdk for this.

>>> is_view("pepper/tf"), is_view("pepper/frame"), is_view("pepper/joints/HeadYaw")
(True, True, False)
>>> view("pepper", LOG)
'pepper/log'
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from sonibus.bus import framing, keys, messages
from sonibus.bus.node import Bus, Reply
from sonibus.bus.streams import Incoming

from . import convert
from .convert import ArmFrames, arm_frames, log_message

FRAME, LOG, TF, DERIVED_INFO = "frame", "log", "tf", "info/derived"
VIEWS = (FRAME, LOG, TF, DERIVED_INFO)
FOXGLOVE = {LOG: convert.LOG, TF: convert.FRAME_TRANSFORMS}  # the views in Foxglove's own schemas
DERIVED_RETRY_S = 2.0  # between questions to <robot>/info/derived while none answered


def view(robot: str, what: str) -> str:
    """The channel of view ``what`` (one of ``VIEWS``) of ``robot``."""
    return f"{robot}/{what}"


def is_view(key: str) -> bool:
    """Whether ``key`` is a view rather than a key taken from the bus (a sink takes
    frames apart into joint keys, the gate refuses ``log`` and ``tf``, and
    ``info/derived`` is only ever asked for)."""
    return key.partition("/")[2] in VIEWS


class Views:
    """The views of what a sink takes (``of``), with what it keeps per robot: its arm
    chains once its info came; and its processors' ``<robot>/info/derived``, asked
    for once derived values of it arrive (answers go to ``on_derived_info`` on a
    Zenoh thread; ``derived_info`` checks one)."""

    def __init__(self, bus: Bus, on_derived_info: Callable[[str, bytes], None]) -> None:
        self.bus, self.on_derived_info = bus, on_derived_info
        self._gate = messages.Gate(bus.limits)
        self._arms: dict[str, ArmFrames | None] = {}
        self._asked: dict[str, float] = {}
        self.derived_seen: set[str] = set()  # robots whose info/derived has been taken

    def of(self, incoming: Incoming, frame: bool = True,
           whole: dict[str, Any] | None = None) -> list[tuple[str, dict[str, Any]]]:
        """The views of one message (a robot's info gives none: it tells its model); without
        ``frame`` a frame's view of itself is left out (the recorder writes the frame as it is);
        ``whole``: the frame's ``selected``, when the caller has it already."""
        robot, section = incoming.source.robot, incoming.source.section
        if section == "info" and not incoming.source.name:
            self._arms[robot] = arm_frames(incoming.message)
        elif section == "events":
            return [(view(robot, LOG), log_message(robot, incoming.message))]
        elif section == "frame" and incoming.values:
            whole = selected(incoming) if whole is None else whole
            arms = self._arms.get(robot)
            out = [(view(robot, FRAME), whole)] if frame else []
            return out if arms is None else [*out, (view(robot, TF), arms.transforms(robot, whole))]
        elif section == "derived" and robot not in self.derived_seen:
            self._ask(robot)
        return []

    def derived_info(self, key: str, payload: bytes) -> dict[str, Any]:
        """An answer handed to ``on_derived_info``, checked by the gate (``ValueError``
        saying what is wrong); its robot is not asked again."""
        message = self._gate.check(keys.Key.parse(key), payload)
        self.derived_seen.add(key.partition("/")[0])
        return message

    def _ask(self, robot: str) -> None:
        now = time.monotonic()
        if now - self._asked.get(robot, -DERIVED_RETRY_S) >= DERIVED_RETRY_S:
            self._asked[robot] = now
            self.bus.ask(keys.derived_info(robot), self._reply, lambda: None, every_answer=True,
                         timeout=DERIVED_RETRY_S)

    def _reply(self, reply: Reply) -> None:  # on a Zenoh thread
        if reply.payload is not None and reply.key == keys.derived_info(reply.key.partition("/")[0]):
            self.on_derived_info(reply.key, reply.payload)


def samples_of(incoming: Incoming) -> list[tuple[str, dict[str, Any]]]:
    """What a message brings, each on its own key: a frame's selected joints (``joint_samples``),
    a derived frame's selected values (``Incoming.parts``, as each came on its key before derived
    frames), or the message itself."""
    if incoming.parts is not None:
        return [(part.source.key, part.message) for part in incoming.parts]
    if incoming.source.section == "frame":
        return joint_samples(incoming)
    return [(incoming.source.key, incoming.message)]


def joint_samples(frame: Incoming) -> list[tuple[str, dict[str, Any]]]:
    """The samples of a frame's selected joints (``Incoming.samples``), each on its joint's key
    (``framing.frame_samples``'s: ``t``, ``seq``, ``v`` and the extra quantities), from its
    ``Selected`` (no ``Incoming`` made per joint)."""
    message, chosen = frame.message, frame.selected
    if chosen is None:
        return []
    t, seq, values = message["t"], message["seq"], message["v"]
    index = range(len(values)) if chosen.indices is None else chosen.indices
    extra = [(q, v) for q, v in message.items() if q not in messages.FRAME_FIELDS]
    if not extra:
        return [(source.key, {"t": t, "seq": seq, "v": values[i]}) for source, i in zip(chosen.sources, index,
                                                                                           strict=True)]
    return [(source.key, {"t": t, "seq": seq, "v": values[i], **{q: v[i] for q, v in extra}})
            for source, i in zip(chosen.sources, index, strict=True)]


def selected(frame: Incoming) -> dict[str, Any]:
    """A frame with only the joints a sink's patterns select (the frame itself when that is all of them;
    from its ``Selected``, worked out once per joint list: no sample made per joint)."""
    message = frame.message
    if frame.selected is None or frame.selected.indices is None:
        return message
    index = frame.selected.indices
    extra = {q: message[q] for q in message if q not in messages.FRAME_FIELDS}
    return framing.frame(message["t"], message["seq"], [message["names"][i] for i in index],
                          [message["v"][i] for i in index], {q: [v[i] for i in index] for q, v in extra.items()})
