"""Whether the robot's basic awareness is on, as the owner's info says it (``awareness``):
ALBasicAwareness enabled and not paused, i.e. the robot looks at people.

Read once per connection (``read``), set by the ``awareness`` command (``took``), and
asked again every status period without waiting (``follow``, from the frame loop: the
answers are taken a period later), so a change made elsewhere (Choregraphe, the robot's
autonomous life) shows within two periods. The info is served on a Zenoh thread: it
reads ``value``, it never asks the robot."""

from __future__ import annotations

import logging
from typing import Any

from .connection import Link, LinkDown, RemoteError

log = logging.getLogger(__name__)

SERVICE = "ALBasicAwareness"


class Awareness:
    """The robot behind ``link``'s basic awareness: ``value`` True, False or None (unknown:
    not connected yet, or a robot without ALBasicAwareness)."""

    def __init__(self, link: Link) -> None:
        self.link = link
        self.value: bool | None = None
        self._changes = 0  # the command's changes: an answer asked before one is out of date
        self._asked: tuple[int, Any, Any] | None = None  # (changes then, isEnabled, isAwarenessPaused futures)

    def read(self) -> None:
        """Ask and wait (on a new connection, after the adapter paused it if it does)."""
        enabled = self.link.try_call(SERVICE, "isEnabled")
        paused = self.link.try_call(SERVICE, "isAwarenessPaused")
        self._asked = None
        self.value = None if enabled is None else bool(enabled) and not paused

    def took(self, enabled: bool) -> None:
        """The ``awareness`` command was carried out (and resumed a pause when ``enabled``)."""
        self._changes += 1
        self.value = bool(enabled)

    def follow(self) -> None:
        """Take the answers asked for last time (if they came and nothing changed since), ask again.
        Not for a robot that had no answer when it was ``read``: its proxy is not there to send on."""
        asked, self._asked = self._asked, None
        if self.value is None:
            return
        if asked is not None and asked[0] == self._changes and all(f.isFinished() and not f.hasError()
                                                                   for f in asked[1:]):
            self.value = bool(asked[1].value()) and not asked[2].value()
        changes = self._changes
        try:
            self._asked = (changes, self.link.start(SERVICE, "isEnabled"),
                           self.link.start(SERVICE, "isAwarenessPaused"))
        except (LinkDown, RemoteError) as exc:  # (not connected now, or a robot without it: known at connection)
            log.debug("basic awareness not asked: %s", exc)
