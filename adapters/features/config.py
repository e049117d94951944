"""Options of the ``features`` processor.

    [nodes.features]
    adapter = "features"
    robots = "pepper"              # or ["pepper", "nao"], or "*"
    cutoff_hz = 5.0
"""

from __future__ import annotations

from dataclasses import dataclass

from sonibus.bus import keys
from sonibus.bus.options import bad

DEFAULT = ("velocity", "hand", "hand_speed", "qom", "motion")
FEATURES = (*DEFAULT, "expressive")  # expressive (opt-in): Laban Efforts, energy, shape, segments (expressive.py)


@dataclass(frozen=True, kw_only=True)
class FeaturesConfig:
    """Options of the ``features`` adapter."""

    robots: str | tuple[str, ...] = "*"       # robot names or patterns ("pepper*")
    features: tuple[str, ...] = DEFAULT       # what to publish
    cutoff_hz: float = 5.0                    # velocity low-pass cut-off
    max_gap_s: float = 0.5                    # a longer pause in a joint's samples restarts its filter
    onset: float = 0.5                        # chain QoM (rad/s) that starts a motion...
    offset: float = 0.2                       # ...and that ends it (lower: hysteresis)
    min_duration_s: float = 0.08              # how long the QoM must stay past a threshold
    fit_window_s: float = 0.4                 # expressive: the derivative fit's window, read at its middle
    laban_window_s: float = 0.5               # expressive: the Efforts' trailing window
    weights: dict[str, float] | None = None   # QoM weight per joint (default: 1 per rad joint, 0 for hands)
    max_wait_ms: float = 50.0                 # per_joint_keys: a frame missing joints is processed after this
    queue: int = 8192                         # messages buffered before the oldest are dropped
    max_age_ms: float = 100.0                 # an older frame is skipped, not computed late (0: never skip)
    per_joint_keys: bool = False              # joints from <robot>/joints/* instead of <robot>/frame
    per_key: bool = False                     # each derived value on its own key, not one frame on <robot>/derived

    def __post_init__(self) -> None:
        found = (self.robots,) if isinstance(self.robots, str) else tuple(self.robots)
        for robot in found:
            if not robot or "/" in robot:
                raise bad("robots", f"'{robot}' is not a robot name or pattern such as \"pepper\" or \"*\"")
        keys.patterns(tuple(keys.joints(r) for r in found), "robots")
        object.__setattr__(self, "robots", found)
        unknown = [f for f in self.features if f not in FEATURES]
        if unknown or not self.features:
            raise bad("features", f"{unknown[0]!r} is unknown — features: {', '.join(FEATURES)}" if unknown
                      else f"is empty — give some of {', '.join(FEATURES)}")
        for key in ("cutoff_hz", "max_gap_s", "max_wait_ms", "fit_window_s", "laban_window_s"):
            if not getattr(self, key) > 0:
                raise bad(key, f"{getattr(self, key):g} must be more than 0")
        if not 0 <= self.offset < self.onset:
            raise bad("offset", f"{self.offset:g} must be at least 0 and below onset ({self.onset:g})")
        if self.min_duration_s < 0:
            raise bad("min_duration_s", f"{self.min_duration_s:g} must be 0 or more")
        for joint, weight in (self.weights or {}).items():
            if not isinstance(weight, int | float) or isinstance(weight, bool) or weight < 0:
                raise bad("weights", f"{joint} = {weight!r} must be a number, 0 or more")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        if not self.max_age_ms >= 0:
            raise bad("max_age_ms", f"{self.max_age_ms:g} must be 0 (never skip) or more")

    def publishes(self, feature: str) -> bool:
        return feature in self.features
