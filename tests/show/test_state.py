"""Issue 37, item 7: the show's state is told when it changes and from the start —
at its time (a gesture under way does not delay the word, only the act), to a sound
patch started after the show (real UDP), and in the lines ``sonibus rehearse`` prints."""

from __future__ import annotations

import signal
import socket
from collections.abc import Iterator

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.show import Show, ShowConfig
from sonibus.adapters.show.clock import start

from ..conftest import SONIBUS, wait_for
from ..test_commands import connect
from .test_show import HEY, commands


@pytest.fixture
def patch() -> Iterator[socket.socket]:
    """The sound patch's UDP port (an independent receiver)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(15)
        yield sock


def test_the_close_is_said_at_its_time_during_a_gesture_and_acted_on_when_it_ends(net):
    """The 3.1 s gesture spans 10:01 (1.5 s in at 20×): "closed" comes before its end, the rest after it."""
    rig = connect(net)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["daily 10:00-10:01"],
                           idle={"behaviors": [HEY]}), name="show")
    show.rehearse(20.0, start("2025-06-03 10:00:30", show.config.zone))
    net.start(show)
    wait_for(lambda: commands(rig)[-1:] == [("stiffness", 0.0)] and rig.events.find("show", state="closed"), 15,
             "the robot at rest")
    told = [(e["kind"], e.get("state")) for e in rig.events.find() if e["kind"] in ("show", "behavior")]
    closed, ended = told.index(("show", "closed")), told.index(("behavior", "stopped"))
    assert closed < ended, told
    assert rig.events.find("show", state="closed")[0]["clock"] == "2025-06-03T10:01:00+02:00"
    assert commands(rig)[-3:] == [("behavior/run", HEY), ("posture", "Crouch"), ("stiffness", 0.0)]


def test_a_sound_patch_started_after_the_show_hears_its_state_at_once_not_a_minute_later(net, patch):
    rig = connect(net)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["tue-sun 10:00-18:00"],
                           announce_every_s=600), name="show")
    show.rehearse(1.0, start("2025-06-02 12:00", show.config.zone))  # a Monday: closed
    net.start(show)  # (as `sonibus run` starts museum.toml's nodes: the show, then the sound)
    net.start(OscSink(OscSinkConfig(subscribe=("pepper/events/*",), targets=(f"127.0.0.1:{patch.getsockname()[1]}",)),
                      name="sound"))
    while not (packet := patch.recv(65536)).startswith(b"/pepper/events/show"):  # (the timeout bounds each wait)
        pass
    assert "closed" in OscMessage(packet).params
    assert rig.events.find("show", state="closed")


def test_rehearse_prints_each_opening_and_closing_with_the_shows_clock(net, spawn, tmp_path):
    config = tmp_path / "day.toml"
    config.write_text("""\
[nodes.pepper]
adapter = "sim"

[nodes.show]
adapter = "show"
robot = "pepper"
timezone = "Europe/Paris"
hours = ["daily 10:00-10:02"]
""", encoding="utf-8")
    process = spawn(SONIBUS, "rehearse", str(config), "--from", "2025-06-03 09:59:30", "--speed", "60",
                    *net.cli_args(), collect=True)
    said = lambda: [line for line in process.lines if "the show is" in line]  # noqa: E731
    wait_for(lambda: len(said()) >= 3, 30, "three changes printed", lambda: "\n".join(process.lines))
    rc, _, err = process.stop(signal.SIGINT, timeout=5)
    assert said()[:3] == ["sonibus: rehearsal: show: the show is closed (Tue 2025-06-03 09:59:30), opens Tue 10:00",
                          "sonibus: rehearsal: show: the show is open (Tue 2025-06-03 10:00:00), closes Tue 10:02",
                          "sonibus: rehearsal: show: the show is closed (Tue 2025-06-03 10:02:00), opens Wed 10:00"], \
        "\n".join(process.lines)
    assert rc == 130 and "Traceback" not in err, err
