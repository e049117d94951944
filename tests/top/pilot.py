"""Driving ``sonibus top``'s app with textual's pilot against a real bus: the app and
its ``Monitor`` on a session of the test network, and waiting without blocking the
app's loop (which must go on redrawing)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any

import pytest
from rich.text import Text
from textual.pilot import Pilot
from textual.widgets import DataTable, Static

from sonibus.bus import Bus
from sonibus.bus.cli.top import TopApp
from sonibus.bus.monitor import Monitor

SIZE = (180, 50)


async def until(pilot: Pilot[Any], predicate: Callable[[], Any], timeout: float = 5.0, what: str = "condition") -> Any:
    """``predicate()`` once it is truthy, the app running meanwhile; fail after ``timeout``."""
    deadline = time.monotonic() + timeout
    while not (value := predicate()):
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        await pilot.pause(0.05)
    return value


def drive(bus: Bus, scenario: Callable[[TopApp, Pilot[Any]], Awaitable[None]]) -> TopApp:
    """Run ``scenario(app, pilot)`` on a ``TopApp`` watching ``bus``; the app (exited or not)."""
    async def run() -> TopApp:
        with Monitor(bus) as monitor:
            app = TopApp(monitor, every_s=0.1)
            async with app.run_test(size=SIZE) as pilot:
                await scenario(app, pilot)
            return app
    return asyncio.run(run())


def shown(app: TopApp, widget: str) -> str:
    """The text of a ``Static`` of the app (``joints``, ``event-lines``, ``status``)."""
    return str(app.query_one(f"#{widget}", Static).content)


def row(app: TopApp, table: str, key: str) -> list[Text] | None:
    """The cells of row ``key`` of table ``robots`` or ``nodes`` (None: not listed)."""
    found = app.query_one(f"#{table}", DataTable)
    return list(found.get_row(key)) if key in found.rows else None
