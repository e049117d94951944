"""Maps made by other libmapper programs (webmapper, a Max patch) that touch a robot's
device: saved as they are made or changed, restored when either end comes back.

libmapper keeps a map only while both its devices run, and a device that restarts
may come back under another ordinal (``synth.1`` → ``synth.2``); a device killed
without saying goodbye stays in the graph until it has not been heard from for
10 s. So a saved map is matched by stable names (``saved.py``), each stable name
resolved to the device of that name heard from most recently, and a map counts as
back only when it joins those very devices.

A map removed while both its ends stay on the network was removed by a person:
it is forgotten (``FORGET_S`` later, not made again meanwhile). A map removed
because one of its ends left is kept.

Runs on the libmapper thread (``Devices`` is not thread-safe).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import libmapper as mpr

from .devices import Devices, endpoints
from .saved import MapFile, SavedMap, split, stable

log = logging.getLogger(__name__)
log.setLevel(logging.INFO)  # (a map that comes back, or not, is said at sonibus run's default level)

HEARD_S = 10.0     # libmapper forgets a device not heard from for this long (its TIMEOUT_SEC)
FORGET_S = 1.5     # a removed map whose ends both stay this long was removed by a person
RETRY_S = 0.3      # a map that is not back this long after it was pushed is pushed again
PUSHED = "pushed, waiting for libmapper"
REFUSED_KEPT = 256  # maps refused for max_maps remembered (so as to say each once)


@dataclass
class _Attempt:
    """Bringing one map back between the devices that carry its names now."""

    at: float                      # when both its ends were seen (monotonic)
    devices: tuple[str, ...]       # the full device names it is made between
    pushed: bool = False           # whether it was made (not while a signal is not there yet)
    pushed_at: float = 0.0         # when it was last tried
    said: bool = False             # whether "did not come back" was said for it


class Keeper:
    """The saved maps of ``file`` (at most ``limit``), kept in step with the graph of ``devices``.
    ``say(kind, text)`` warns (rate-limited by the node), ``count(kind)`` counts."""

    def __init__(self, file: MapFile, devices: Devices, limit: int, restore_s: float,
                 say: Callable[[str, str], None], count: Callable[[str], None]) -> None:
        self.file, self.devices, self.limit, self.restore_s = file, devices, limit, restore_s
        self.say, self.count = say, count
        loaded = file.load()  # (ValueError: the node does not start, the file is left as it is)
        if len(loaded) > limit:
            say("maps_refused", f"{file.path}: {len(loaded)} maps, only the first {limit} are kept "
                                f"(max_maps = {limit})")
        self.wanted: dict[tuple[tuple[str, ...], str], SavedMap] = {m.key: m for m in loaded[:limit]}
        self.removed: dict[tuple[tuple[str, ...], str], tuple[float, tuple[str, ...]]] = {}  # when, between what
        self.attempts: dict[tuple[tuple[str, ...], str], _Attempt] = {}
        self.waiting: dict[tuple[tuple[str, ...], str], str] = {}   # what each map that is not back waits for
        self.live: set[tuple[tuple[str, ...], str]] = set()
        self.ready_since: float | None = None  # since when every device of ours has had its name (monotonic)
        self._said_absent: set[tuple[tuple[str, ...], str]] = set()
        self._refused: set[tuple[tuple[str, ...], str]] = set()  # maps not kept for max_maps, said once each
        self.snapshot: dict[str, Any] = {}  # for the node's stats (read on another thread: replaced whole)

    # -- what the graph says ----------------------------------------------------------

    def changed(self, found: Any, present: bool) -> None:
        """A map of the graph appeared, changed (``present``) or went."""
        ends = endpoints(found)
        if ends is None:
            return
        sources, destination = ends
        if not any(self.devices.ours(e.full) for e in (*sources, destination)):
            return  # (a map between two other programs: theirs to keep)
        expression = found[mpr.Property.EXPRESSION]
        muted = found[mpr.Property.MUTED]
        seen = SavedMap(tuple(e.name for e in sources), destination.name,
                        str(expression) if expression else "", bool(muted))
        if not present:
            if seen.key in self.wanted and seen.key not in self.attempts:  # (not one being brought back)
                self.removed[seen.key] = (time.monotonic(), tuple(e.full for e in (*sources, destination)))
            return
        if not found.get_is_ready():
            return  # (staged: saved once it runs)
        self.removed.pop(seen.key, None)
        if seen.key in self.attempts and seen.key in self.wanted:
            # back as it runs, not at the next tick: a person's unmap that comes before it (a busy machine)
            # would be taken for one of a map being brought back, and the map made again
            self._back(seen.key, self.wanted[seen.key], time.monotonic())
        if self.wanted.get(seen.key) == seen:
            return
        if seen.key not in self.wanted and len(self.wanted) >= self.limit:
            if seen.key in self._refused:  # (said once: each graph tells of it, and again as it changes)
                return
            if len(self._refused) >= REFUSED_KEPT:
                self._refused.clear()
            self._refused.add(seen.key)
            self.count("maps_refused")
            self.say("maps_refused", f"map {seen.describe()} not saved: already {self.limit} maps in "
                                     f"{self.file.path} (max_maps) — remove some, or raise max_maps")
            return
        new = seen.key not in self.wanted
        self.wanted[seen.key] = seen
        log.info("libmapper: map %s %s (expression %r)", seen.describe(), "saved" if new else "changed",
                 seen.expression)
        self._save()

    def left(self, device: str) -> None:
        """A device left the network: the maps removed with it were not removed by a person."""
        for key in [k for k, (_, between) in self.removed.items() if device in between]:
            del self.removed[key]

    def _save(self) -> None:
        try:
            self.file.save(list(self.wanted.values()))
            self.count("maps_saved")
        except OSError as exc:
            self.count("errors")
            self.say("maps_file", f"maps not saved to {self.file.path}: {exc.strerror or exc} — they run, but "
                                  "will not come back after a restart")

    # -- what to do about it ------------------------------------------------------------

    def current(self) -> dict[str, str]:
        """Stable device name → the full name of the device it is now: ours once it has its name,
        and of the others the one heard from most recently (within ``HEARD_S``)."""
        chosen: dict[str, tuple[float, str]] = {}
        now = time.time()
        for name, synced in self.devices.remote():
            stable_name = stable(name)
            if now - synced > HEARD_S or stable_name in self.devices.robots:
                continue  # (a robot of ours is our device alone, once it has its name: never a dead one of before)
            if stable_name not in chosen or synced > chosen[stable_name][0]:
                chosen[stable_name] = (synced, name)
        out = {s: name for s, (_, name) in chosen.items()}
        for served in self.devices.robots.values():
            if served.ready:
                out[served.robot] = served.name
        return out

    def tick(self) -> None:
        """Forget maps a person removed; push back those that are not there; say those that do
        not come back within ``restore_s``."""
        now = time.monotonic()
        current = self.current()
        was_live, self.live = self.live, self._live(current)
        # A map that ran and runs no more while its ends stay is a person's removal, whether or not the
        # graph told of it (under load its callback had not come, and the map was pushed back: made again)
        for key in was_live - self.live:
            saved = self.wanted.get(key)
            if saved is not None and key not in self.removed and all(d in current for d in saved.devices):
                self.removed[key] = (now, tuple(current[d] for d in saved.devices))
        ready = bool(self.devices.robots) and all(s.ready for s in self.devices.robots.values())
        self.ready_since = (self.ready_since or now) if ready else None
        for key, (at, _) in list(self.removed.items()):
            if now - at < FORGET_S:
                continue
            del self.removed[key]
            saved = self.wanted.get(key)
            if saved is not None and key not in self.live and all(d in current for d in saved.devices):
                del self.wanted[key]
                log.info("libmapper: map %s removed while both its ends run: forgotten", saved.describe())
                self._save()
        for table in (self.attempts, self.waiting):  # (bounded by the maps kept)
            for key in [k for k in table if k not in self.wanted]:
                del table[key]
        self._said_absent &= self.wanted.keys()
        for key, saved in self.wanted.items():
            if key in self.live:
                self._back(key, saved, now)
                continue
            if key in self.removed:  # (removed while both ends ran, as far as is known yet: not made again)
                continue
            absent = [d for d in saved.devices if d not in current]
            if absent:
                self.waiting[key] = f"device {', '.join(repr(d) for d in absent)} not on the network"
                if self.ready_since is not None and now - self.ready_since >= self.restore_s \
                        and key not in self._said_absent:
                    self._said_absent.add(key)
                    self.count("maps_not_back")
                    self.say(f"absent:{saved.describe()}", f"map {saved.describe()} not back: "
                                                           f"{self.waiting[key]} (it comes back when it does)")
                continue
            devices = tuple(current[d] for d in saved.devices)
            attempt = self.attempts.get(key)
            if attempt is None or attempt.devices != devices:  # (the clock starts when both ends are seen)
                attempt = self.attempts[key] = _Attempt(now, devices)
            if not attempt.pushed or now - attempt.pushed_at >= RETRY_S:
                self.waiting[key] = self._push(saved, current)
                attempt.pushed, attempt.pushed_at = self.waiting[key] == PUSHED, now
            if not attempt.said and now - attempt.at >= self.restore_s:
                attempt.said = True
                self.count("maps_not_back")
                self.say(f"not_back:{saved.describe()}", f"map {saved.describe()} did not come back within "
                                                         f"{self.restore_s:g} s of both its ends being on the "
                                                         f"network ({self.waiting[key]})")
        self.snapshot = self._snapshot()

    def _back(self, key: tuple[tuple[str, ...], str], saved: SavedMap, now: float) -> None:
        attempt = self.attempts.pop(key, None)
        self.waiting.pop(key, None)
        if attempt is not None:
            log.info("libmapper: map %s back, %.0f ms after both its ends were on the network", saved.describe(),
                     (now - attempt.at) * 1000)
        elif key in self._said_absent:
            log.info("libmapper: map %s back", saved.describe())
        self._said_absent.discard(key)

    def _live(self, current: dict[str, str]) -> set[tuple[tuple[str, ...], str]]:
        live = set()
        for found in self.devices.running():
            ends = endpoints(found)
            if ends is None or not found.get_is_ready():
                continue
            sources, destination = ends
            if all(current.get(e.device) == e.full for e in (*sources, destination)):
                live.add((tuple(e.name for e in sources), destination.name))
        return live

    def _push(self, saved: SavedMap, current: dict[str, str]) -> str:
        """Make ``saved`` between the current devices, through the manager graph; what is missing,
        or ``PUSHED``. (After a restart of ours, a peer may still hold the map it had with our old
        device under the very name of our new one, ``pepper.1``, but not its ports: the first push
        then does nothing, a push ``RETRY_S`` later takes; seen here, back in about 0.7 s.)"""
        signals = []
        for device, signal in ((current[d], s) for d, s in map(split, (*saved.sources, saved.destination))):
            found = self.devices.signal(device, signal)
            if found is None:
                return f"{device} has no signal '{signal}'"
            signals.append(found)
        made = mpr.Map(signals[:-1], signals[-1])
        if saved.expression:
            made[mpr.Property.EXPRESSION] = saved.expression
        if saved.muted:
            made[mpr.Property.MUTED] = True
        made.push()
        return PUSHED

    def _snapshot(self) -> dict[str, Any]:
        missing = [f"{self.wanted[k].describe()}: {why}" for k, why in self.waiting.items() if k in self.wanted]
        shown = "; ".join(missing[:5]) + (f"; and {len(missing) - 5} more" if len(missing) > 5 else "")
        return {"maps_kept": len(self.wanted), "maps_live": len(self.live), "maps_missing": len(missing),
                "maps_missing_why": shown}

