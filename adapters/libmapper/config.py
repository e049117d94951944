"""Options of the ``libmapper`` adapter.

    [nodes.mapper]
    adapter = "libmapper"
    interface = "eth0"               # the network libmapper discovers on ("": libmapper's choice)
    maps = "libmapper-maps.json"     # maps made in webmapper, kept here (beside the installation file)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sonibus.bus.options import bad

MAX_MAPS = 1024  # the most maps= can be set to


@dataclass(frozen=True)
class LibmapperConfig:
    """Options of the ``libmapper`` adapter."""

    interface: str = ""                   # network interface libmapper uses ("": the one it picks, often not lo)
    maps: str = "libmapper-maps.json"     # where maps are saved; a relative path is taken beside the installation file
    robots: tuple[str, ...] = ()          # robots served as devices (empty: every robot on the bus)
    commands: bool = True                 # input signals that command the robot (joints/set); false: outputs only
    command_hz: float = 20.0              # joints/set sent to one robot at most this often (latest values win)
    speed: float = 0.3                    # joints/set speed, a fraction of each joint's maximum velocity
    timeout: float = 2.0                  # seconds a robot has to answer a command
    max_maps: int = 256                   # maps kept in the file; more are refused, said in the log
    restore_s: float = 1.0                # a saved map not back this long after both its ends are seen is said
    queue: int = 4096                     # frames waiting for the libmapper thread; past this the oldest are dropped

    def __post_init__(self) -> None:
        if any(c in self.interface for c in "/ \t\n") or len(self.interface) > 15:
            raise bad("interface", f"{self.interface!r} is not an interface name (as `ip link` lists them)")
        if not self.maps.strip():
            raise bad("maps", "is empty — name the JSON file maps are saved in")
        if not (math.isfinite(self.command_hz) and 0 < self.command_hz <= 100):
            raise bad("command_hz", f"{self.command_hz:g} must be in (0, 100]")
        if not (math.isfinite(self.speed) and 0 < self.speed <= 1):
            raise bad("speed", f"{self.speed:g} must be in (0, 1] (a fraction of each joint's maximum velocity)")
        if not (math.isfinite(self.timeout) and self.timeout > 0):
            raise bad("timeout", f"{self.timeout:g} s must be more than 0")
        if not 1 <= self.max_maps <= MAX_MAPS:
            raise bad("max_maps", f"{self.max_maps} must be in 1..{MAX_MAPS}")
        if not (math.isfinite(self.restore_s) and 0 < self.restore_s <= 60):
            raise bad("restore_s", f"{self.restore_s:g} s must be in (0, 60]")
        if self.queue < 16:
            raise bad("queue", f"{self.queue} must be at least 16")
