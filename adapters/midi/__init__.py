"""MIDI for DAWs and synths: the sink ``midi`` (joints → CC / pitch bend, events →
notes) and the controller ``midi-in`` (faders, keys, programs → robot commands).

    from sonibus.adapters.midi import MidiSink, MidiSinkConfig
    sink = MidiSink(MidiSinkConfig(port="sonibus"), name="daw")
"""

from .config import MidiControllerConfig, MidiSinkConfig
from .controller import MidiController
from .sink import MidiSink

__all__ = ["MidiController", "MidiControllerConfig", "MidiSink", "MidiSinkConfig"]
