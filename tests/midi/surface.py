"""A MIDI controller in a process of its own: JACK client ``surface`` with output port
``fader`` (JACK-Client). ``flood N`` writes up to N CC 7 messages (channel 1, unmapped in
the tests) as fast as JACK's MIDI buffer takes them, ``note N`` a note on N, again each
second (a note written in the cycle its connection is made may reach nobody: a CI run's
node never heard the one note). It prints ``ready`` when its port is there, starts once
something connects to it (printing ``connected``), and waits to be killed.

    python tests/midi/surface.py flood 500000
"""

from __future__ import annotations

import sys
import threading
import time

import jack

PER_PERIOD = 300  # messages a period (256 frames at 48 kHz: 56,000 a second)


def main(mode: str, number: int) -> None:
    client = jack.Client("surface", no_start_server=True)
    port = client.midi_outports.register("fader")
    left = [0]

    @client.set_process_callback
    def process(frames: int) -> None:
        port.clear_buffer()
        try:
            for offset in range(min(PER_PERIOD, left[0])):
                if mode == "flood":
                    port.write_midi_event(offset * frames // PER_PERIOD, (0xB0, 7, left[0] % 128))
                else:
                    port.write_midi_event(0, (0x90, number, 100))
                left[0] -= 1
        except jack.JackError:  # JACK's MIDI buffer is full: the rest next period
            pass

    client.activate()
    print("ready", flush=True)
    deadline = time.monotonic() + 10
    while not port.connections and time.monotonic() < deadline:
        time.sleep(0.01)
    left[0] = number if mode == "flood" else 1
    print("connected" if port.connections else "nobody connected", flush=True)
    while mode == "note":
        time.sleep(1.0)
        left[0] = 1
    threading.Event().wait()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
