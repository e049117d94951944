"""A plug-in adapter outside the sonibus tree: writes samples as JSON lines."""

from __future__ import annotations

import json
from dataclasses import dataclass

from sonibus.bus import Adapter, decode


@dataclass(frozen=True)
class JsonLinesConfig:
    path: str
    subscribe: str = "*/joints/*"


class JsonLinesSink(Adapter):
    """Appends every sample of a key expression to a file, one JSON object a line."""

    Config = JsonLinesConfig

    def _start(self) -> None:
        self._file = self.own(open(self.config.path, "a", encoding="utf-8"))  # noqa: SIM115 - closed by stop()
        subscriber, self._queue = self.bus.subscribe(self.config.subscribe)
        self.own(subscriber)
        self.spawn(self._write, "write")

    def _write(self) -> None:
        while not self.stopping.is_set():
            item = self._queue.get(timeout=0.2)
            if item is not None:
                key, payload = item
                self._file.write(json.dumps({"key": key, **decode(payload)}) + "\n")
                self._file.flush()
