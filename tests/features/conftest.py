"""What the features tests share: a robot's info, a fake owner that publishes
exactly the frames a test wants, and synthetic trajectories."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

import numpy as np
import pytest

from sonibus import schemas
from sonibus.bus import codec, framing, keys, load_model

T0 = 1_700_000_000.0  # frames carry UNIX times


def model_info(model: str, robot: str | None = None) -> dict[str, Any]:
    """``<robot>/info`` as a robot owner of ``model`` serves it (the parts the processor reads)."""
    return {"robot": robot or model, "model": model, "rate_hz": 100.0,
            "joints": [j.to_info() for j in load_model(model).joints]}


class FakeOwner:
    """Serves ``<robot>/info`` (a full robot info: what ``info`` leaves out filled in) and
    publishes joint frames as a test writes them: whole on ``<robot>/frame`` and then per
    joint, as a robot owner does."""

    def __init__(self, bus: Any, robot: str, info: dict[str, Any]) -> None:
        self.bus, self.robot, self.seq = bus, robot, 0
        info = {"robot": robot, "rate_hz": 100.0, "behaviors": [], "postures": [], "adapter": "FakeOwner",
                "schema_version": schemas.VERSION, "owner": {"host": bus.host, "node": f"owner-{robot}"}, **info}
        payload = codec.encode(info)
        self.queryable = bus.serve(keys.info(robot), lambda q: q.reply(keys.info(robot), payload,
                                                                       encoding=codec.ENCODING))
        self._publishers: dict[str, Any] = {}

    def frame(self, t: float, positions: Mapping[str, Any], seq: int | None = None,
              whole: bool = True, joints: bool = True) -> int:
        """One frame: every joint of ``positions`` at ``t`` (values may be NaN); returns its seq.
        ``whole=False`` puts the joint keys only (as a script of one's own may), ``joints=False``
        the frame only."""
        self.seq = self.seq + 1 if seq is None else seq
        if whole:
            self.put(keys.frame(self.robot), framing.frame(t, self.seq, list(positions), list(positions.values())))
        for joint, value in positions.items() if joints else ():
            self.put(keys.joint(self.robot, joint), {"t": t, "seq": self.seq, "v": value})
        return self.seq

    def put(self, key: str, message: dict[str, Any] | bytes) -> None:
        """``message`` (encoded unless bytes already) on ``key``."""
        if key not in self._publishers:
            self._publishers[key] = self.bus.session.declare_publisher(key)
        self._publishers[key].put(message if isinstance(message, bytes) else codec.encode(message))

    def close(self) -> None:
        self.queryable.undeclare()
        for publisher in self._publishers.values():
            publisher.undeclare()


@pytest.fixture
def owner(net) -> Iterator[Callable[..., FakeOwner]]:
    made: list[FakeOwner] = []

    def make(robot: str, info: dict[str, Any]) -> FakeOwner:
        made.append(FakeOwner(net.bus(f"owner-{robot}"), robot, info))
        return made[-1]

    yield make
    for fake in made:
        fake.close()


def gesture(t: np.ndarray, start: float, duration: float, amplitude: float) -> np.ndarray:
    """A smooth out-and-back movement (raised cosine) from ``start``, lasting ``duration``."""
    x = np.clip((t - start) / duration, 0.0, 1.0)
    return amplitude * 0.5 * (1.0 - np.cos(2.0 * np.pi * x))


from ..midi.conftest import jack, reader  # noqa: E402, F401  (JACK fixtures for the MIDI sink test)
