"""Opening ports: a virtual port others see, and a useful error for an unknown one."""

from __future__ import annotations

import pytest
import rtmidi

from sonibus.adapters.midi import MidiController, MidiControllerConfig, MidiSink, MidiSinkConfig
from sonibus.bus import ConfigError

from ..conftest import wait_for
from ..jackd import MidiInput


def test_the_sink_opens_a_virtual_port_others_see(net, jack):
    net.start(MidiSink(MidiSinkConfig(api="jack", port="robots"), name="daw"))
    probe = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "probe")
    wait_for(lambda: "daw:robots" in probe.get_ports(), what="the virtual port listed")
    probe.delete()


def test_an_unknown_port_is_an_error_listing_the_ports(net, jack, writer):
    synth = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "synth")
    synth.open_virtual_port("keys")
    try:
        with pytest.raises(ConfigError, match=r"key 'connect': no MIDI output port matches 'nosuch'.*'synth:keys'"):
            net.start(MidiSink(MidiSinkConfig(api="jack", connect="nosuch"), name="daw"))
        with pytest.raises(ConfigError, match=r"key 'connect': no MIDI output port matches 'nosuch'.*'surface:fader'"):
            net.start(MidiController(MidiControllerConfig(api="jack", connect="nosuch"), name="surface-in"))
    finally:
        synth.close_port()
        synth.delete()


def test_connect_opens_an_existing_port_by_substring(net, jack):
    synth = MidiInput("synth", virtual="keys")
    try:
        net.start(MidiSink(MidiSinkConfig(api="jack", connect="KEYS"), name="daw"))
        net.sim("pepper", rate_hz=50)
        wait_for(lambda: len(synth.messages) >= 5, what="MIDI at the connected port")
    finally:
        synth.close()
