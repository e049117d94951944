"""Options of the ``hear`` adapter.

    [nodes.ears]
    adapter = "hear"
    listen = ["pepper/audio/speaker"]   # what a JACK input plays into the robot; "pepper/audio/mic" its microphones

>>> HearConfig(listen=("pepper/audio/mic",)).streams
(('pepper', 'mic'),)
>>> HearConfig(listen=("pepper/audio/ears",))  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
sonibus.bus.errors.ConfigError: key 'listen': 'pepper/audio/ears' is not an audio key — give ROBOT/audio/mic ...
"""

from __future__ import annotations

from dataclasses import dataclass

from sonibus.bus import keys
from sonibus.bus.options import bad

MAX_STREAMS = 64  # audio keys one node listens to


@dataclass(frozen=True, kw_only=True)
class HearConfig:
    """Options of the ``hear`` adapter (docs/mapping.md, "Audio features")."""

    listen: tuple[str, ...] = ("pepper/audio/mic",)  # ROBOT/audio/mic or ROBOT/audio/speaker keys
    onset_db: float = 12.0        # a chunk this many dB over the background is an onset
    onset_min_db: float = -50.0   # ... and at least this loud
    onset_hold_ms: float = 150.0  # the onset value stays 1 this long; no other onset within it
    quiet_ms: float = 60.0        # no chunk for this long (a sender that sends no digital silence): silence
    centroid_max_hz: float = 20000.0  # the centroid's declared range is 0..this (values beyond are clamped)
    queue: int = 256              # chunks waiting for the worker before the oldest are dropped

    def __post_init__(self) -> None:
        if not self.listen:
            raise bad("listen", "is empty — give at least one audio key, e.g. [\"pepper/audio/mic\"]")
        if len(self.listen) > MAX_STREAMS:
            raise bad("listen", f"{len(self.listen)} audio keys, at most {MAX_STREAMS} in one node")
        self.streams  # (checks each key)  # noqa: B018
        if not self.onset_db > 0:
            raise bad("onset_db", f"{self.onset_db:g} must be more than 0 (dB)")
        if not -100.0 < self.onset_min_db < 0:
            raise bad("onset_min_db", f"{self.onset_min_db:g} must be between -100 and 0 (dB full scale)")
        for key in ("onset_hold_ms", "quiet_ms"):
            if not 0 < getattr(self, key) <= 10_000:
                raise bad(key, f"{getattr(self, key):g} must be more than 0 and at most 10000 (ms)")
        if not 0 < self.centroid_max_hz <= 96_000:
            raise bad("centroid_max_hz", f"{self.centroid_max_hz:g} must be more than 0 and at most 96000 (Hz)")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def streams(self) -> tuple[tuple[str, str], ...]:
        """Each listened key as (robot, stream)."""
        out = []
        for key in self.listen:
            chunks = key.split("/") if isinstance(key, str) else ()
            if len(chunks) != 3 or chunks[1] != "audio" or chunks[2] not in keys.AUDIO_STREAMS:
                raise bad("listen", f"{key!r} is not an audio key — give ROBOT/audio/mic (its microphones) or "
                                    "ROBOT/audio/speaker (a JACK input, what it plays)".replace('"', "'"))
            try:
                keys.check_name("robot", chunks[0])
            except ValueError as exc:
                raise bad("listen", str(exc)) from None
            out.append((chunks[0], chunks[2]))
        if len(set(out)) < len(out):
            raise bad("listen", "names an audio key twice")
        return tuple(out)
