"""The controller through a real JACK MIDI port: faders move the simulated robot,
keys run behaviors, program changes pick postures, a panic key stops."""

from __future__ import annotations

import time

import pytest

from sonibus.adapters.midi import MidiController, MidiControllerConfig
from sonibus.adapters.show import Show, ShowConfig
from sonibus.bus import ConfigError, decode, load_model

from ..conftest import wait_for
from ..wakes import calls, left_after_stop

HEY = "animations/Stand/Gestures/Hey_1"


def controller(net, **options):
    return net.start(MidiController(MidiControllerConfig(api="jack", connect="surface:fader", **options),
                                    name="surface-in"))


def latest(queue):
    """The newest value waiting in ``queue`` (None if none)."""
    value = None
    while (item := queue.get(timeout=0)) is not None:
        value = decode(item[1])
    return value


def test_a_fader_sweep_moves_the_joint_within_its_limits(net, writer):
    net.sim("pepper", rate_hz=50)
    surface = controller(net, cc=({"cc": 7, "channel": 2, "robot": "pepper", "joint": "HeadYaw", "speed": 1.0},),
                         rate_hz=20)
    limits = load_model("pepper").joint("HeadYaw")
    _, queue = net.bus("watch").subscribe("pepper/joints/HeadYaw")
    seen: list[float] = []

    def watched():
        sample = latest(queue)
        if sample is not None:
            seen.append(sample["v"])
        return sample

    started = time.monotonic()
    for value in range(128):  # a sweep up at 500 messages/s, as a fast fader (JACK drops bigger bursts)
        writer.send_message([0xB1, 7, value])
        time.sleep(0.002)
    wait_for(lambda: watched() and seen[-1] > limits.max - 0.01, timeout=10, what="HeadYaw at its maximum")
    for value in [*range(127, 0, -8), 0]:           # and back down
        writer.send_message([0xB1, 7, value])
        time.sleep(0.002)
    wait_for(lambda: watched() and seen[-1] < limits.min + 0.01, timeout=10, what="HeadYaw at its minimum")
    elapsed = time.monotonic() - started
    assert all(limits.min - 1e-6 <= v <= limits.max + 1e-6 for v in seen)
    assert surface.stats["errors"] == 0
    # JACK's dummy driver may drop a message or two of a burst on a loaded machine, so count loosely
    assert 100 < surface.stats["received"] <= 128 + 17
    # fader moves are coalesced: at most rate_hz commands a second, however long the sweeps took
    assert surface.stats["commands"] <= 20 * elapsed + 2, (surface.stats["commands"], f"{elapsed:.2f} s")


def test_a_key_runs_a_behavior_and_its_release_stops_it(net, writer):
    net.sim("pepper", rate_hz=50)
    controller(net, notes=({"note": 60, "robot": "pepper", "behavior": HEY, "stop_on_release": True},))
    _, events = net.bus("watch").subscribe("pepper/events/behavior")
    writer.send_message([0x90, 60, 100])
    got: list[dict] = []

    def state(wanted):
        while (item := events.get(timeout=0)) is not None:
            got.append(decode(item[1]))
        return any(e["name"] == HEY and e["state"] == wanted for e in got)

    wait_for(lambda: state("started"), what="the behavior started")
    writer.send_message([0x80, 60, 0])
    wait_for(lambda: state("stopped"), what="the behavior stopped on release")


def test_a_key_mapped_to_a_scenario_asks_the_robots_show_for_it(net, writer):
    net.sim("pepper", rate_hz=50, words_per_minute=600)
    net.start(Show(ShowConfig(robot="pepper", scenarios={"hello": {"steps": [{"say": "Hello"}]}}), name="show"))
    _, events = net.bus("watch").subscribe("pepper/events/scenario")
    surface = controller(net, notes=({"note": 61, "robot": "pepper", "scenario": "hello"},))
    got: list[dict] = []

    def seen(state):
        while (item := events.get(timeout=0)) is not None:
            got.append(decode(item[1]))
        return any(e["name"] == "hello" and e["state"] == state and e["by"] == "midi" for e in got)

    asker = net.bus("ask")
    wait_for(lambda: [r for r in asker.query("pepper/program/status", {}) if r["result"]["available"]], 10,
             "the show to take the robot")
    writer.send_message([0x90, 61, 100])
    wait_for(lambda: seen("ended"), 10, "the scenario asked by the key, to its end")
    assert surface.stats["ok"] == 1


def test_program_change_picks_a_posture_and_the_panic_key_stops(net, writer):
    net.sim("pepper", rate_hz=50)
    surface = controller(net, program=({"robot": "pepper", "postures": ["StandInit", "Crouch"], "speed": 1.0},),
                         stop=({"robot": "pepper", "cc": 119},))
    _, events = net.bus("watch").subscribe("pepper/events/*")
    writer.send_message([0xC0, 1])
    writer.send_message([0xB0, 119, 127])
    got: list[dict] = []

    def seen(kind, **fields):
        while (item := events.get(timeout=0)) is not None:
            got.append(decode(item[1]))
        return any(e["kind"] == kind and all(e.get(k) == v for k, v in fields.items()) for e in got)

    wait_for(lambda: seen("posture", name="Crouch", state="started"), what="Crouch started")
    wait_for(lambda: seen("command", verb="stop"), what="stop sent")
    wait_for(lambda: surface.stats["ok"] == 2, what="both answered")


def test_a_refused_command_is_logged_once(net, writer, caplog):
    net.sim("pepper", rate_hz=50)
    surface = controller(net, notes=({"note": 61, "robot": "pepper", "behavior": "no/such/behavior"},))
    for _ in range(3):
        writer.send_message([0x90, 61, 100])
    wait_for(lambda: surface.stats["errors"] == 3, what="three refusals")
    assert caplog.text.count("no/such/behavior") == 1


@pytest.mark.parametrize(("options", "message"), [
    ({"cc": ({"cc": 1, "robot": "pepper", "joint": "Tail"},)}, r"key 'cc'.*key 'joint': pepper has no joint 'Tail'"),
    ({"cc": ({"cc": 1, "robot": "nao2", "joint": "HipPitch"},)}, r"nao2 has no joint 'HipPitch'"),
    ({"cc": ({"cc": 1, "robot": "pepper", "joint": "HeadYaw", "speed": 2.0},)}, r"key 'speed'"),
    ({"notes": ({"note": 128, "robot": "pepper", "behavior": "x"},)}, r"key 'notes'.*key 'note': 128"),
    ({"stop": ({"robot": "pepper"},)}, r"key 'stop'.*exactly one of note or cc"),
    ({"rate_hz": 0.0}, r"key 'rate_hz'"),
])
def test_bad_options_name_the_key(options, message):
    with pytest.raises(ConfigError, match=message):
        MidiControllerConfig(**options)


def test_an_unknown_joint_of_an_unknown_model_is_reported_when_info_arrives(net, writer, caplog):
    net.sim("robo", model="pepper", rate_hz=50)
    surface = controller(net, cc=({"cc": 1, "robot": "robo", "joint": "Tail"},))
    wait_for(lambda: surface.stats["errors"] >= 1, what="the unknown joint reported")
    assert "key 'cc': robo has no joint 'Tail'" in caplog.text


def test_an_idle_controller_sleeps_until_a_message_or_a_port_change(net, writer):
    """With no fader moved, the commands worker and the JACK watch have nothing to do: they sleep
    (before: 0.2 s and 0.5 s timeouts, 5 and 2 wake-ups a second; issue 35). Stopped, they end at once."""
    node = controller(net, cc=({"cc": 7, "channel": 2, "robot": "pepper", "joint": "HeadYaw"},))
    wait_for(lambda: node._jack.connected, what="the controller's port connected")
    counted = calls({"commands": (node._queue, "get"), "watch": (node._jack.changed, "wait")}, 3.0)
    assert counted["commands"] <= 1 and counted["watch"] <= 2, counted
    assert not left_after_stop(node, "surface-in:")  # (each woken by the stop: not left to its join's 2 s)


def test_a_fader_of_a_robot_without_info_waits_for_it_without_spinning(net, writer):
    """A fader moved for a robot whose limits are not known yet (no owner answers its info) is held
    until they are: the worker asks again every INFO_RETRY_S, and sleeps between (before: it woke
    with a timeout of 0, over and over, counting ``waiting_info`` each time)."""
    node = controller(net, cc=({"cc": 7, "channel": 2, "robot": "ghost", "joint": "HeadYaw"},))
    wait_for(lambda: node._jack.connected, what="the controller's port connected")
    writer.send_message([0xB1, 7, 64])
    wait_for(lambda: node.stats["waiting_info"], what="the fader held for ghost's info")
    counted = calls({"commands": (node._queue, "get")}, 2.0)
    # (one ask in 2 s: the wait until it, and one after; before: waits of 0, over and over)
    assert counted["commands"] <= 3, counted
    assert node.stats["waiting_info"] <= 4, dict(node.stats)
    node.stop()  # (before JACK's server, the fixtures' teardown: not a client it must drop)
