"""A plug-in outside the sonibus tree: an adapter that writes samples as JSON lines,
and a subcommand that counts them."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

from sonibus.bus import Adapter, decode
from sonibus.bus.cli import Command, Environment


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


def _count_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="a file written by the jsonl sink")


def _count(args: argparse.Namespace, env: Environment) -> int:
    with open(args.file, encoding="utf-8") as f:
        env.say(f"{sum(1 for _ in f)} lines")
    return 0


COUNT = Command("jsonl-count", "count the lines a jsonl sink wrote", _count_arguments, _count)
