"""A robot owner's publishers: the whole frame on ``<robot>/frame`` (what sinks
subscribe to), then each joint's sample on ``<robot>/joints/<Joint>`` — only while
anyone subscribes there, since per-joint keys cost an encode and a put per joint.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import zenoh

from . import codec, framing, keys
from .node import Bus, Entities


class FramePublishers:
    """``put(frame)`` for one robot, with the publishers it needs declared ahead
    (``joints``: those known before the first frame)."""

    def __init__(self, bus: Bus, robot: str, joints: Iterable[str] = ()) -> None:
        self.bus, self.robot = bus, robot
        self._frame = bus.stream_publisher(keys.frame(robot))
        self._joints: dict[str, zenoh.Publisher] = {}
        self.per_joint = False  # whether anyone subscribes to the robot's joint keys now
        self._encoder = codec.FrameEncoder(())  # (made again for the names of the first frame, then kept)
        self._watch = bus.watch_subscribers(keys.joints(robot), self._wanted)
        for joint in joints:
            self._joint(joint)

    def _wanted(self, matching: bool) -> None:
        self.per_joint = matching

    def put(self, frame: dict[str, Any]) -> None:
        """Publish ``frame`` (checked by the caller: ``framing.frame``, ``valid_part``)."""
        self._frame.put(codec.encode(frame))
        if self.per_joint:
            for name, sample in framing.frame_samples(frame):
                self._joint(name).put(codec.encode(sample))

    def put_values(self, t: float, seq: int, names: Sequence[str], values: Sequence[float]) -> None:
        """Publish the frame of ``values`` (one per name, each a ``float`` within range:
        ``messages.plain_floats``; no other quantity), the same bytes as ``put`` of it, with
        its names packed once for all frames (``codec.FrameEncoder``)."""
        encoder = self._encoder
        if names is not encoder.names and tuple(names) != encoder.names:  # (a robot's joints: the same each frame)
            encoder = self._encoder = codec.FrameEncoder(names)
        self._frame.put(encoder.encode(t, seq, values))
        if self.per_joint:
            for name, sample in framing.frame_samples(framing.frame(t, seq, names, values)):
                self._joint(name).put(codec.encode(sample))

    def _joint(self, name: str) -> zenoh.Publisher:
        publisher = self._joints.get(name)
        if publisher is None:  # also a joint the robot reports beyond its reference model
            publisher = self._joints[name] = self.bus.stream_publisher(keys.joint(self.robot, name))
        return publisher

    def undeclare(self) -> None:
        entities = Entities((self._watch, *self._joints.values(), self._frame))
        self._joints.clear()
        entities.undeclare()
