"""The sink through a real JACK MIDI port: scaling, 14-bit, pitch bend, dedupe,
the rate cap, channels, events as notes, frames or joint keys, and bad frames."""

from __future__ import annotations

import logging
import re
import time
from pathlib import Path

import pytest
import rtmidi

from sonibus.adapters.midi import MidiSink, MidiSinkConfig
from sonibus.adapters.midi.mapping import behavior_note
from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import ConfigError, encode, keys

from ..conftest import queued_keys, wait_for
from ..wakes import left_after_stop, named, wakes


def sink(net, **options):
    return net.start(MidiSink(MidiSinkConfig(api="jack", **options), name="daw"))


def until_sent(robot, joint, value, reader, expected, what):
    """Put ``value`` until ``expected`` arrives (the first samples wait for ``<robot>/info``)."""
    def arrived():
        robot.joint(joint, value)
        return expected(reader)
    wait_for(arrived, what=what)


def test_seven_bit_controllers_by_joint_order_at_limits_and_mid_range(net, fake, reader):
    sink(net)
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", -2.0, midi, lambda r: r.cc(1, 20) == [0], "A at its minimum on CC 20")
    for value in (-2.0, -2.0, 2.0, 2.0, 0.0, 0.0, 3.5):    # beyond the limit: clamped
        bot.joint("A", value)
    bot.joint("B", 0.25)
    wait_for(lambda: midi.cc(1, 21) == [32], what="B a quarter up on CC 21")
    assert midi.cc(1, 20) == [0, 127, 64, 127]             # only changes are sent


def test_fourteen_bit_and_pitch_bend(net, fake, reader):
    sink(net, auto_map=False, map=({"key": "bot/joints/A", "cc": 1, "resolution": 14},
                                   {"key": "bot/joints/B", "pitchbend": True, "channel": 3}))
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", -2.0, midi, lambda r: r.cc(1, 33) == [0], "A at its minimum, LSB on CC 33")
    bot.joint("A", 2.0)
    bot.joint("A", 0.0)
    bot.joint("A", 1.0)                                     # 12287.25 → 12287 = 95 * 128 + 127
    bot.joint("B", 1.0)
    bot.joint("B", 0.5)
    bot.joint("B", 0.0)
    wait_for(lambda: [0xE2, 0, 0] in midi.messages, what="pitch bend at its minimum")
    assert list(zip(midi.cc(1, 1), midi.cc(1, 33), strict=True)) == [(0, 0), (127, 127), (64, 0), (95, 127)]
    bends = [m for m in midi.messages if m[0] == 0xE2]
    assert bends == [[0xE2, 127, 127], [0xE2, 0, 64], [0xE2, 0, 0]]  # LSB first, 8192 = centre
    assert not any(m[0] & 0xF0 == 0xB0 and m[1] in (20, 21) for m in midi.messages)  # auto_map off


def test_the_rate_cap_keeps_the_newest_value(net, fake, reader):
    daw = sink(net, max_rate_hz=10)
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", -2.0, midi, lambda r: r.cc(1, 20) == [0], "the first value")
    first = len(midi.messages)
    started = time.monotonic()
    for step in range(1, 201):            # a fast sweep: 200 values as fast as they go
        bot.joint("A", -2.0 + step * 0.02)
    wait_for(lambda: midi.cc(1, 20)[-1:] == [127], what="the newest value after the sweep")
    sent = len(midi.messages) - first
    # at most 10 a second for as long as it took (a fraction of a second; longer on a busy machine)
    allowed = 10 * (time.monotonic() - started) + 2
    assert sent <= allowed, f"{sent} messages (at most {allowed:.0f}) for a sweep of ~{daw.stats['held']} held values"
    assert daw.stats["held"] > 100


def test_channels_in_the_order_robots_are_first_seen(net, fake, reader):
    daw = sink(net, channels={"late": 9})
    midi = reader("daw:sonibus")
    one, two, late = fake("one"), fake("two"), fake("late")
    until_sent(one, "A", 2.0, midi, lambda r: r.cc(1, 20) == [127], "robot one on channel 1")
    until_sent(two, "A", 2.0, midi, lambda r: r.cc(2, 20) == [127], "robot two on channel 2")
    until_sent(late, "B", 1.0, midi, lambda r: r.cc(9, 21) == [127], "the fixed channel")
    assert daw.channels == {"one": 1, "two": 2, "late": 9}


@pytest.mark.parametrize("per_joint_keys", [False, True], ids=["frames", "joint-keys"])
def test_frames_are_heard_or_with_per_joint_keys_the_joint_keys(net, fake, reader, per_joint_keys):
    """A robot owner puts both; a script may put only one: the sink hears what its option says."""
    daw = sink(net, per_joint_keys=per_joint_keys)
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", 0.0, midi, lambda r: r.cc(1, 20) == [64], "A mid-range from frames and joint keys")
    bot.joint("B", 1.0)
    wait_for(lambda: midi.cc(1, 21) == [127], what="B at its maximum: what was put before is taken")
    received = daw.stats["received"]
    bot.frame({"A": 2.0, "B": 0.0}, whole=per_joint_keys, joints=not per_joint_keys)    # not heard
    bot.frame({"A": -2.0, "B": 0.5}, whole=not per_joint_keys, joints=per_joint_keys)   # heard, after it
    wait_for(lambda: midi.cc(1, 21) == [127, 64], what="B half up")
    assert midi.cc(1, 20) == [64, 0]
    assert daw.stats["received"] == received + 2     # each joint once, never twice


BAD_FRAMES = [
    b"\xc1 not msgpack",
    encode({"t": 1.0, "seq": 1, "names": ["A", "B"], "v": [0.5]}),    # a value short
    encode({"t": 1.0, "seq": 1, "names": ["A"], "v": [None]}),
    encode({"t": 1.0, "names": ["A"], "v": [0.5]}),                    # no seq
    encode({"t": 1.0, "seq": 1, "names": ["A?"], "v": [0.5]}),         # a wildcard in the name
]


def test_a_malformed_frame_is_counted_and_the_sink_goes_on(net, fake, reader):
    daw = sink(net)
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", 0.0, midi, lambda r: r.cc(1, 20) == [64], "A mid-range")
    for payload in BAD_FRAMES:
        bot.bus.session.put(keys.frame("bot"), payload)
    bot.joint("A", 2.0)                       # after the bad ones, from the same session
    wait_for(lambda: midi.cc(1, 20) == [64, 127], what="A at its maximum after the bad frames")
    assert daw.stats["bad"] == len(BAD_FRAMES)
    assert daw.state == "running"


def test_events_as_notes_and_connection_lost_silences_every_channel(net, fake, reader, caplog):
    sink(net)
    midi = reader("daw:sonibus")
    bot, other = fake("bot"), fake("other")
    until_sent(other, "A", 0.0, midi, lambda r: r.cc(1, 20) == [64], "robot other on channel 1")
    nod, unlisted = behavior_note("nod"), behavior_note("unlisted")
    assert (nod, unlisted, behavior_note("wave")) == (105, 65, 65)  # CRC-32 of the names onto 60..127
    bot.event("behavior", name="wave", state="stopped")     # a note off without its note on: nothing
    bot.event("behavior", name="nod", state="started")
    wait_for(lambda: [0x91, nod, 100] in midi.messages, what="nod's note on, on channel 2")
    bot.event("behavior", name="nod", state="stopped")
    bot.event("behavior", name="unlisted", state="started")
    bot.event("speech", text="hello", state="started")
    bot.event("speech", text="hello", state="done")
    bot.event("connection", state="lost")
    wait_for(lambda: [0xB1, 123, 0] in midi.messages, what="all notes off")
    notes = [m for m in midi.messages if m[0] & 0xF0 in (0x80, 0x90) or m[1] == 123]
    assert notes == [[0x91, nod, 100], [0x81, nod, 0], [0x91, unlisted, 100], [0x91, 48, 100], [0x81, 48, 0],
                     [0xB0, 123, 0], [0xB1, 123, 0]]
    assert "bot: behaviors 'wave' and 'unlisted' share note 65 — give one a note of its own: " \
           "behavior_notes = {\"unlisted\" = N}" in caplog.text


def test_behavior_notes_stay_put_when_behaviors_are_installed(net, fake, reader):
    """Issue 19, item 7: a behavior's note was its index in the robot's list, so one more
    behavior installed renumbered every note of a live set."""
    sink(net, behavior_notes={"jump": 70})
    midi = reader("daw:sonibus")
    before = fake("bot", behaviors=("wave", "nod"))
    after = fake("bot2", behaviors=("aaa", "jump", "wave", "nod"))  # the same robot, more installed
    until_sent(before, "A", 0.0, midi, lambda r: r.cc(1, 20) == [64], "bot on channel 1")
    until_sent(after, "A", 0.0, midi, lambda r: r.cc(2, 20) == [64], "bot2 on channel 2")
    for robot in (before, after, after):
        robot.event("behavior", name="nod", state="started")
        robot.event("behavior", name="nod", state="stopped")
    after.event("behavior", name="jump", state="started")
    wait_for(lambda: [0x91, 70, 100] in midi.messages, what="jump on the note behavior_notes gives it")
    ons = sorted(m for m in midi.messages if m[0] in (0x90, 0x91))  # (the two robots' events interleave)
    assert ons == [[0x90, 105, 100], [0x91, 70, 100], [0x91, 105, 100], [0x91, 105, 100]]


def test_a_fixed_behavior_note(net, fake, reader):
    sink(net, behavior_note=36, speech_note=37)
    midi = reader("daw:sonibus")
    bot = fake()
    bot.event("behavior", name="wave", state="started")
    bot.event("speech", text="hi", state="started")
    wait_for(lambda: [0x90, 37, 100] in midi.messages, what="the speech note")
    assert midi.messages == [[0x90, 36, 100], [0x90, 37, 100]]


def test_a_hardware_port_warns_of_too_many_messages(net, fake, jack, caplog):
    synth = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "synth")
    synth.open_virtual_port("din")
    try:
        caplog.set_level(logging.WARNING)
        daw = sink(net, connect="synth:din")
        bot = fake("bot", joints=tuple((f"J{i}", 0.0, 1.0) for i in range(17)), rate_hz=100)
        wait_for(lambda: (bot.joint("J0", 0.5), daw.estimated_rate)[1], what="the estimate")
        assert daw.estimated_rate == 1700
        assert "about 1700 MIDI messages/s to 'synth:din'" in caplog.text
    finally:
        synth.close_port()
        synth.delete()


@pytest.mark.parametrize(("options", "message"), [
    ({"map": ({"key": "pepper/joints/HeadYaw", "cc": 40, "resolution": 14},)},
     r"key 'map'.*key 'cc': 40 must be in 0\.\.31"),
    ({"map": ({"key": "pepper/joints/HeadYaw"},)}, r"key 'cc': -1 must be in 0\.\.119"),
    ({"map": ({"key": "pepper/joints/*", "cc": 1},)}, r"key 'key': 'pepper/joints/\*' is not a joint key"),
    ({"map": ({"key": "pepper/joints/HeadYaw", "cc": 1}, {"key": "pepper/joints/HeadPitch", "cc": 1})},
     r"same key or controller"),
    ({"channels": {"pepper": 17}}, r"key 'channels': pepper = 17 must be a channel in 1\.\.16"),
    ({"port": ""}, r"key 'port': is empty"),
    ({"max_rate_hz": -1.0}, r"key 'max_rate_hz'"),
    ({"behavior_notes": {"Hey_1": 128}}, r"key 'behavior_notes': 'Hey_1' = 128 must be a note in 0\.\.127"),
    ({"behavior_note_range": (100, 60)}, r"key 'behavior_note_range': \[100, 60\] must be two notes"),
])
def test_bad_options_name_the_key(options, message):
    with pytest.raises(ConfigError, match=message):
        MidiSinkConfig(**options)


def test_a_robot_that_leaves_the_bus_silences_its_notes(net, reader):
    """No `connection` event from anyone: the robot's owner just vanishes (a crash, a cut
    link); the sink learns it from liveliness and sends all-notes-off."""
    from sonibus.bus import robot_info, send_command

    sink(net)
    midi = reader("daw:sonibus")
    robot = net.sim("pepper", rate_hz=20)
    bus = net.bus("cmd")
    wait_for(lambda: robot_info(bus, "pepper", timeout=0.5), what="pepper/info")
    wait_for(lambda: midi.cc(1, 20), what="pepper's joints on channel 1")
    send_command(bus, "pepper", "behavior/run", {"name": "animations/Stand/Gestures/Hey_1"})
    wait_for(lambda: any(m[0] == 0x90 for m in midi.messages), what="the behavior's note on")
    robot.stop()
    wait_for(lambda: [0xB0, 123, 0] in midi.messages, what="all notes off when pepper leaves")


def test_the_docs_give_the_simulators_behavior_notes():
    """docs/midi.md's note table is what the sink plays for the simulator (it said 60 for
    Hey_1, which played 64)."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "midi.md").read_text(encoding="utf-8")
    documented = {name: int(note) for note, name in re.findall(r"^\| (\d+) \| `(animations/[^`]+)` \|$", text, re.M)}
    assert documented == {name: behavior_note(name) for name in LIBRARY}


def test_frames_are_played_where_they_arrive_not_through_the_queue(net, fake, reader):
    """A robot's frames are played on the subscription's callback thread, as the OSC sink
    sends them (a thread hand-off a frame less: issue 35, docs/performance.md)."""
    daw = sink(net)
    midi = reader("daw:sonibus")
    bot = fake()
    until_sent(bot, "A", -2.0, midi, lambda r: r.cc(1, 20)[-1:] == [0], "A at its minimum")
    queued = queued_keys(daw._queue)
    for step in range(1, 11):  # (a tick's spacing: not paced)
        bot.frame({"A": -2.0 + 0.4 * step}, joints=False)
        time.sleep(0.02)
    wait_for(lambda: midi.cc(1, 20)[-1:] == [127], what="A at its maximum, ten frames on")
    assert len(midi.cc(1, 20)) >= 11
    assert queued.count("bot/frame") <= 1, queued  # (one may meet the worker holding the state)


def test_an_idle_sinks_workers_sleep_until_there_is_work(net, reader):
    """With a robot streaming, its frames played where they arrive, the forward worker has nothing
    to do, and presence's watch nothing until the robot may fall silent: they sleep (before: 0.2 s
    and 0.5 s timeouts, 5 and 2 wake-ups a second; issue 35). Stopped, they end at once."""
    daw = sink(net)
    midi = reader("daw:sonibus")
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: len(midi.messages) >= 10, what="pepper's frames at the MIDI port")
    wait_for(lambda: not daw._presence.unsaid, what="pepper's state told (presence's rounds until then)")
    counted = wakes(named("daw:"), 3.0)
    # (a count: a thread that waits for the GIL counts a switch too; before: forward 15, silence 6)
    assert counted["daw:forward"] <= 3 and counted["daw:silence"] <= 3, counted
    assert not left_after_stop(daw, "daw:")  # (each woken by the stop: not left to its join's 2 s)
