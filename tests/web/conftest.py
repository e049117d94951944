"""Fixtures of the web pages' tests (server and browser): a simulated ``pepper`` and a
``web`` node on a private loopback bus, with an operator token, a kiosk token and two
kiosk buttons; and a WebSocket client (aiohttp) that gathers what the server sends.

    def test_x(stage):
        stage.operator_url      # http://127.0.0.1:<port>/?token=...
        stage.kiosk_url         # http://127.0.0.1:<port>/kiosk?token=...
        stage.sim               # the SimRobot; stage.net the Network (net.bus() for a test session)
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import aiohttp
import pytest

from sonibus.adapters.sim import SimRobot
from sonibus.adapters.web import WebConfig, WebPages
from sonibus.bus import Bus, codec, keys

from ..conftest import Network, wait_for
from ..oscquery.conftest import Socket as QuerySocket
from ..oscquery.conftest import opener
from .browser import Browser

RATE = 50                 # frames/s of the simulated robot
TOKEN = "operator-secret-1"
KIOSK_TOKEN = "kiosk-secret-2"
WAVE = "animations/Stand/Gestures/Hey_1"  # a sim behavior of about 3 s
HELLO = "Hello, visitors!"
NOTICE_SHOWN = "return document.getElementById('notice').checkVisibility()"  # (the kiosk's "One moment")
BUTTONS = [{"id": "wave", "label": "Wave hello", "behavior": WAVE},
           {"id": "hello", "label": "Say hello", "say": HELLO}]


@dataclass
class Stage:
    """The running nodes and the pages' URLs (tokens included)."""

    net: Network
    sim: SimRobot
    node: WebPages

    @property
    def url(self) -> str:
        return self.node.url

    @property
    def operator_url(self) -> str:
        return f"{self.url}/?token={TOKEN}"

    @property
    def kiosk_url(self) -> str:
        return f"{self.url}/kiosk?token={KIOSK_TOKEN}"

    def ws_url(self, role: str = "operator", token: str | None = None) -> str:
        token = (TOKEN if role == "operator" else KIOSK_TOKEN) if token is None else token
        path = "/ws" if role == "operator" else "/kiosk/ws"
        return self.url.replace("http://", "ws://") + path + (f"?token={token}" if token else "")


def start_web(net: Network, name: str = "web", **options: Any) -> WebPages:
    """A ``web`` node on ``net`` listening on a free loopback port (``options``: WebConfig's)."""
    config = WebConfig(**{"listen": "127.0.0.1:0", **options})
    return net.start(WebPages(config, name=name))


@pytest.fixture
def stage(net: Network) -> Stage:
    """A simulated ``pepper`` (``RATE`` frames/s, idle motion on) and a web node showing it,
    with tokens and the kiosk's ``BUTTONS``; pepper's info already known to the node."""
    sim = net.sim("pepper", rate_hz=RATE, idle=True)
    node = start_web(net, token=TOKEN, kiosk_token=KIOSK_TOKEN, kiosk={"robot": "pepper", "buttons": BUTTONS})
    wait_for(lambda: "pepper" in node.shown_robots(), 10, "pepper's info at the web node")
    return Stage(net, sim, node)


class Socket(QuerySocket):
    """A WebSocket client on a loop of its own (the OSCQuery tests' client, opened at
    ``url`` as given): ``send`` JSON, ``messages`` as they come, ``of``/``wait`` the
    decoded ones of a type; ``closed`` once the server closed it."""

    def __init__(self, url: str) -> None:
        self.given_url = url
        super().__init__(url)

    async def _open(self) -> None:
        self._session = aiohttp.ClientSession()
        self._ws = await self._session.ws_connect(self.given_url)
        self._reader = asyncio.create_task(self._read())

    def of(self, type_: str, /, **fields: Any) -> list[dict[str, Any]]:
        """The messages of type ``type_`` whose ``fields`` are as given."""
        return [m for m in self.texts() if m.get("type") == type_ and all(m.get(k) == v for k, v in fields.items())]

    def wait(self, type_: str, /, timeout: float = 10.0, **fields: Any) -> dict[str, Any]:
        """The first message of type ``type_`` with ``fields`` (waiting for it)."""
        return wait_for(lambda: (self.of(type_, **fields) or [None])[0], timeout, f"a {type_} message {fields}",
                        lambda: f"got: {[m.get('type') for m in self.texts()][-20:]}")


@pytest.fixture
def websocket() -> Iterator[Callable[[str], Socket]]:
    """``websocket(url)`` opens a client, closed at the end of the test."""
    yield from opener(Socket)


@pytest.fixture(scope="session")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Browser]:
    """One Chromium for every page test (each opens its own page of its own server, in the
    window size it asks for: ``Browser.open``)."""
    chromium = Browser(tmp_path_factory.mktemp("chromium-profile"))
    try:
        yield chromium
    finally:
        chromium.quit()


class Watch:
    """What the robot publishes, read on the test's own session: events and frames, in order."""

    def __init__(self, bus: Bus, robot: str = "pepper") -> None:
        self._event_sub, self._events = bus.subscribe(f"{robot}/events/*", maxlen=100_000)
        self._frame_sub, self._frames = bus.subscribe(keys.frame(robot), maxlen=100_000)
        self.events: list[tuple[str, dict[str, Any]]] = []  # (kind, event)
        self.frames: list[dict[str, Any]] = []
        # Routes to a new subscriber take a moment: once frames come, the events (declared first) do too.
        wait_for(lambda: self.update() or self.frames, 10, f"{robot}'s frames at the test's session")

    def update(self) -> None:
        for key, payload in self._events.drain(0):
            self.events.append((key.rsplit("/", 1)[1], codec.decode(payload)))
        for _, payload in self._frames.drain(0):
            self.frames.append(codec.decode(payload))

    def event(self, kind: str, **fields: Any) -> list[dict[str, Any]]:
        """Events of ``kind`` whose ``fields`` are as given, oldest first."""
        self.update()
        return [e for k, e in self.events if k == kind and all(e.get(f) == v for f, v in fields.items())]

    def commands(self, verb: str) -> list[dict[str, Any]]:
        """The robot's notices of ``verb`` commands it answered."""
        return self.event("command", verb=verb)

    def wait_event(self, kind: str, what: str, **fields: Any) -> dict[str, Any]:
        return wait_for(lambda: self.event(kind, **fields), 10, what, lambda: f"events: {self.events[-10:]}")[0]

    def value(self, joint: str) -> float:
        """``joint`` in the newest frame (NaN before the first)."""
        self.update()
        if not self.frames:
            return math.nan
        frame = self.frames[-1]
        return frame["v"][frame["names"].index(joint)]

    def still(self, frames: int) -> bool:
        """Whether the last ``frames`` frames are all the same pose (the robot halted)."""
        self.update()
        last = self.frames[-frames:]
        return len(last) == frames and all(f["v"] == last[0]["v"] for f in last)


def open_operator(browser: Browser, stage: Stage) -> None:
    """The operator page with pepper's panel shown (with other robots, the first by name would be)."""
    browser.open(f"{stage.operator_url}#pepper")
    browser.wait(lambda: browser.attribute("#connection", "data-state") == "connected", "the page connected")
    browser.wait(lambda: (browser.text('[data-robot="pepper"] [data-joint="HeadYaw"]') or "–") != "–",
                 "pepper's HeadYaw shown")
