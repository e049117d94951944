"""Maps as sonibus keeps them: by stable names, in a JSON file.

libmapper names a device ``<name>.<ordinal>`` and chooses the ordinal when the
device starts (``pepper.1``, after a restart maybe ``pepper.2``), so a map is kept
by its devices' names without the ordinal and its signals' names:

>>> stable("pepper.1"), stable("synth.12"), stable("odd")
('pepper', 'synth', 'odd')
>>> m = SavedMap(("listener/yaw",), "pepper/cmd/joints/set/HeadYaw", "y=x$0*2")
>>> m.describe(), m.devices
('listener/yaw -> pepper/cmd/joints/set/HeadYaw', ('listener', 'pepper'))
>>> SavedMap.from_json(m.to_json()) == m
True
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

MAX_SOURCES = 8          # sources of one map (libmapper's convergent maps take a few)
MAX_NAME = 256           # characters of a device/signal name kept
MAX_EXPRESSION = 4096    # characters of an expression kept
MAX_FILE = 4 << 20       # bytes of a maps file read
_ORDINAL = re.compile(r"^(.+)\.(\d+)$")


def stable(device_name: str) -> str:
    """A device's name without libmapper's ordinal (``pepper.3`` → ``pepper``)."""
    found = _ORDINAL.match(device_name)
    return found[1] if found else device_name


class Endpoint(NamedTuple):
    """One end of a map: the device's stable name, the signal's name, the device's full name."""

    device: str
    signal: str
    full: str = ""

    @property
    def name(self) -> str:
        """``pepper/joints/HeadYaw``: what the file keeps."""
        return f"{self.device}/{self.signal}"


def split(name: str) -> tuple[str, str]:
    """``pepper/joints/HeadYaw`` → ``("pepper", "joints/HeadYaw")``; ``ValueError`` if not so shaped."""
    device, _, signal = name.partition("/")
    if not device or not signal or len(name) > MAX_NAME:
        raise ValueError(f"{name[:80]!r} is not <device>/<signal>")
    return device, signal


@dataclass(frozen=True)
class SavedMap:
    """A map by stable names: sources (in the expression's order, ``x$0``...), destination, expression."""

    sources: tuple[str, ...]
    destination: str
    expression: str = ""
    muted: bool = False

    @property
    def key(self) -> tuple[tuple[str, ...], str]:
        """What tells two maps apart (libmapper allows one map per set of sources and destination)."""
        return self.sources, self.destination

    @property
    def devices(self) -> tuple[str, ...]:
        """The stable names of every device it joins, sorted."""
        return tuple(sorted({split(n)[0] for n in (*self.sources, self.destination)}))

    def describe(self) -> str:
        return f"{', '.join(self.sources)} -> {self.destination}"

    def to_json(self) -> dict[str, Any]:
        return {"sources": list(self.sources), "destination": self.destination, "expression": self.expression,
                "muted": self.muted}

    @classmethod
    def from_json(cls, data: Any) -> SavedMap:
        """``ValueError`` naming what is wrong."""
        if not isinstance(data, dict):
            raise ValueError("a map must be an object with sources, destination and expression")
        sources, destination = data.get("sources"), data.get("destination")
        expression, muted = data.get("expression", ""), data.get("muted", False)
        if not isinstance(sources, list) or not 1 <= len(sources) <= MAX_SOURCES:
            raise ValueError(f"sources must be a list of 1..{MAX_SOURCES} '<device>/<signal>' names")
        for name in (*sources, destination):
            if not isinstance(name, str):
                raise ValueError(f"{name!r} is not a '<device>/<signal>' name")
            split(name)
        if not isinstance(expression, str) or len(expression) > MAX_EXPRESSION:
            raise ValueError(f"expression must be a string of at most {MAX_EXPRESSION} characters")
        if not isinstance(muted, bool):
            raise ValueError("muted must be true or false")
        return cls(tuple(sources), destination, expression, muted)


class MapFile:
    """The file maps are kept in: read at start, written whole (a new file renamed over
    the old one: a crash leaves the old or the new, never half)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def load(self) -> list[SavedMap]:
        """The maps kept; none if there is no file. ``ValueError`` with the file and the
        problem for a file that cannot be read: it is left as it is (nothing lost)."""
        try:
            with self.path.open("rb") as f:
                raw = f.read(MAX_FILE + 1)
        except FileNotFoundError:
            return []
        except OSError as exc:
            raise ValueError(f"{self.path}: cannot read: {exc.strerror}") from None
        if len(raw) > MAX_FILE:
            raise ValueError(f"{self.path}: larger than {MAX_FILE >> 20} MiB — not a maps file of this node")
        try:
            data = json.loads(raw)
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"{self.path}: not valid JSON: {exc} — fix it or move it away") from None
        maps = data.get("maps") if isinstance(data, dict) else None
        if not isinstance(maps, list):
            raise ValueError(f"{self.path}: no \"maps\" list — fix it or move it away")
        out = []
        for index, entry in enumerate(maps):
            try:
                out.append(SavedMap.from_json(entry))
            except ValueError as exc:
                raise ValueError(f"{self.path}: map {index + 1}: {exc} — fix it or remove it") from None
        return out

    def save(self, maps: list[SavedMap]) -> None:
        """Write ``maps``; ``OSError`` if it cannot be written."""
        text = json.dumps({"version": 1, "maps": [m.to_json() for m in maps]}, indent=2) + "\n"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            temporary.write_text(text, encoding="utf-8")
            os.replace(temporary, self.path)
        finally:
            temporary.unlink(missing_ok=True)
