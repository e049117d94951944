"""Issue 37, item 7, on the pages (real headless Chromium): a robot whose show is closed
shows it and its next opening on the operator's line and on the kiosk (buttons dimmed);
a gesture asked of it while its motors rest is refused, and nothing runs — no
behavior event on the bus, nothing for the sound patch (real UDP)."""

from __future__ import annotations

import socket

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.show import Show, ShowConfig
from sonibus.adapters.show.clock import start
from sonibus.bus import send_command

from ..conftest import Network, wait_for
from ..show import test_state
from .browser import Browser
from .conftest import BUTTONS, KIOSK_TOKEN, TOKEN, Stage, Watch, open_operator, start_web

NOD = "animations/Stand/Gestures/Yes_1"
patch = test_state.patch  # (the fixture: the sound patch's UDP port)


@pytest.fixture
def closed_stage(net: Network, patch: socket.socket) -> Stage:
    """pepper, its show closed (a Monday: opens Tue 10:00) and resting, a sound patch and the pages."""
    sim = net.sim("pepper", rate_hz=50, idle=False)
    net.start(OscSink(OscSinkConfig(subscribe=("pepper/events/*",), targets=(f"127.0.0.1:{patch.getsockname()[1]}",)),
                      name="sound"))
    node = start_web(net, token=TOKEN, kiosk_token=KIOSK_TOKEN, kiosk={"robot": "pepper", "buttons": BUTTONS})
    wait_for(lambda: "pepper" in node.shown_robots(), 10, "pepper's info at the web node")
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["tue-sun 10:00-18:00"]), name="show")
    show.rehearse(1.0, start("2025-06-02 12:00", show.config.zone))
    watch = Watch(net.bus("watch"))
    net.start(show)
    wait_for(lambda: watch.event("command", verb="stiffness"), 10, "pepper put to rest by its show")
    return Stage(net, sim, node)


def heard(patch: socket.socket, prefix: bytes) -> list[OscMessage]:
    """What the patch got until the first message starting with ``prefix`` (that one last)."""
    got = [OscMessage(patch.recv(65536))]
    while not got[-1].dgram.startswith(prefix):
        got.append(OscMessage(patch.recv(65536)))
    return got


def test_a_gesture_asked_while_closed_and_resting_is_refused_and_nothing_runs(closed_stage, browser: Browser,
                                                                            patch):
    watch = Watch(closed_stage.net.bus("watch"))
    open_operator(browser, closed_stage)
    line = '[data-summary="pepper"] .summary-show'
    browser.wait(lambda: browser.text(line) == "show closed, opens Tue 10:00", "the show's state on the line")
    browser.wait(lambda: "motors off" in (browser.attribute(line, "title") or ""), "its rest on the line")
    browser.find(f'[data-robot="pepper"] [data-behavior="{NOD}"]').click()
    browser.wait(lambda: "closed: the robot rests until Tue 10:00; a supervisor may wake it" in browser.text("#status"),
                 "the refusal on the status line")
    assert browser.attribute(f'[data-robot="pepper"] [data-behavior="{NOD}"]', "data-state") != "running"
    # a barrier: a sentence (no motors needed) after the refused click; nothing of a behavior before its end
    send_command(closed_stage.net.bus("sender"), "pepper", "say", {"text": "after"})
    before = heard(patch, b"/pepper/events/speech")
    assert not [m for m in before if m.address == "/pepper/events/behavior"], [m.address for m in before]
    assert not watch.event("behavior") and not watch.commands("behavior/run")
    assert browser.errors() == []


def test_the_kiosk_says_closed_and_the_next_opening_with_its_buttons_dimmed(closed_stage, browser: Browser):
    browser.open(closed_stage.kiosk_url)
    browser.wait(lambda: browser.js("return sonibus.link.connected"), "the kiosk connected")
    browser.wait(lambda: browser.text("#show") == "closed, opens Tue 10:00", "the show's state on the kiosk")
    assert not any(button.is_enabled() for button in browser.all("[data-button]"))
    assert browser.js("return getComputedStyle(document.querySelector('[data-button]')).opacity") == "0.4"
    assert browser.errors() == []
