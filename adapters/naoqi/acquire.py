"""Reading joints: one batched read per frame, timed.

``almemory``: one ``ALMemory.getListData(keys)`` holds every position, every
extra quantity and any polled event key. ``motion``: ``ALMotion.getAngles(names,
True)`` (and ``getAngles(names, False)`` for ``cmd``) sent together with the
``getListData`` of the rest, so a frame costs one round trip either way.

A polled key that ALMemory does not hold yet (``ALTextToSpeech/TextDone`` on a
robot that has not spoken since it booted) is "not raised yet": its value is
None, the frame is read without it, and it is asked for again every
``PROBE_EVERY_S`` (beside a frame's read) until it exists."""

from __future__ import annotations

import statistics
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .connection import Link, RemoteError

MEMORY = "Device/SubDeviceList/{}/{}"
POSITION = "Position/Sensor/Value"
PROBE_EVERY_S = 0.2  # how often polled keys that do not exist yet are looked for (a text lasts longer)
QUANTITIES = {"cmd": "Position/Actuator/Value", "cur": "ElectricCurrent/Sensor/Value",
              "temp": "Temperature/Sensor/Value"}


@dataclass(frozen=True)
class Reading:
    """One read: ``t`` (wall clock, middle of the round trip), positions and extra
    quantities in the reader's joint order, polled ALMemory keys (None: not raised yet), read time."""

    t: float
    positions: list[float]
    extra: dict[str, list[float]]
    polled: dict[str, Any]
    read_s: float


class Reader:
    """Reads ``names`` from ``source`` (almemory | motion), plus ``extra`` quantities
    and ``polled`` ALMemory keys, in one round trip per frame."""

    def __init__(self, link: Link, names: Sequence[str], source: str, extra: Sequence[str] = (),
                 polled: Sequence[str] = ()) -> None:
        self.link, self.names, self.source = link, list(names), source
        self.extra, self.polled = tuple(extra), tuple(polled)
        self.keys: list[str] = []
        self._slices: dict[str, slice] = {}
        if source == "almemory":
            self._add("v", [MEMORY.format(n, POSITION) for n in self.names])
        for quantity in self.extra:
            if not (source == "motion" and quantity == "cmd"):
                self._add(quantity, [MEMORY.format(n, QUANTITIES[quantity]) for n in self.names])
        self.polling = False         # the polled keys exist and are read with every frame
        self._next_probe = 0.0       # until then: when to look for them again

    def _add(self, part: str, keys: list[str]) -> None:
        self._slices[part] = slice(len(self.keys), len(self.keys) + len(keys))
        self.keys.extend(keys)

    def read(self) -> Reading:
        wall, started = time.time(), time.monotonic()
        calls = {}
        if self.source == "motion":
            calls["v"] = ("ALMotion.getAngles", self.link.start("ALMotion", "getAngles", self.names, True))
            if "cmd" in self.extra:
                calls["cmd"] = ("ALMotion.getAngles", self.link.start("ALMotion", "getAngles", self.names, False))
        keys = [*self.keys, *self.polled] if self.polling else self.keys
        if keys:
            calls["memory"] = ("ALMemory.getListData", self.link.start("ALMemory", "getListData", keys))
        probe = None
        if self.polled and not self.polling and started >= self._next_probe:
            probe = self.link.start("ALMemory", "getListData", list(self.polled))
        results = {part: list(self.link.wait(future, what)) for part, (what, future) in calls.items()}
        read_s = time.monotonic() - started
        memory = results.pop("memory", [])
        parts = {part: memory[where] for part, where in self._slices.items()} | results
        positions = [float(v) for v in parts["v"]]
        if len(positions) != len(self.names):
            raise ValueError(f"asked for {len(self.names)} joints, got {len(positions)} values")
        polled = dict(zip(self.polled, memory[len(self.keys):], strict=True)) if self.polling else \
            dict.fromkeys(self.polled)
        if probe is not None:
            polled = self._probed(probe, polled)
        return Reading(wall + read_s / 2, positions, {q: [float(v) for v in parts[q]] for q in self.extra},
                     polled, read_s)

    def _probed(self, probe: Any, polled: dict[str, Any]) -> dict[str, Any]:
        """The polled keys' values once they all exist (from now on read with every frame)."""
        try:
            values = list(self.link.wait(probe, "ALMemory.getListData"))
        except RemoteError:  # not raised yet
            self._next_probe = time.monotonic() + PROBE_EVERY_S
            return polled
        self.polling = True
        return dict(zip(self.polled, values, strict=True))


class ReadTimes:
    """Achieved frame rate and read latency over the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 5.0) -> None:
        self.window_s = window_s
        self._reads: deque[tuple[float, float]] = deque()  # (monotonic time, read seconds)
        self._lock = threading.Lock()

    def add(self, read_s: float) -> None:
        now = time.monotonic()
        with self._lock:
            self._reads.append((now, read_s))
            while self._reads and self._reads[0][0] < now - self.window_s:
                self._reads.popleft()

    def reads(self) -> list[float]:
        """Read times (s) of the frames in the window."""
        with self._lock:
            return [r for _, r in self._reads]

    def clear(self) -> None:
        with self._lock:
            self._reads.clear()

    def summary(self) -> dict[str, float]:
        """``rate_hz`` achieved, ``read_ms`` median and ``read_ms_max`` (0 without frames)."""
        with self._lock:
            frames = list(self._reads)
        if len(frames) < 2:
            return {"rate_hz": 0.0, "read_ms": 0.0, "read_ms_max": 0.0}
        span = frames[-1][0] - frames[0][0]
        reads = [r * 1000.0 for _, r in frames]
        return {"rate_hz": round((len(frames) - 1) / span, 2) if span > 0 else 0.0,
                "read_ms": round(statistics.median(reads), 3), "read_ms_max": round(max(reads), 3)}
