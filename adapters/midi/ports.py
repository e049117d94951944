"""MIDI ports through python-rtmidi: open a virtual port of our own, or connect
to an existing one by name or substring (mido's rtmidi backend does neither the
substring nor a client named after the node when connecting: docs/midi.md).

>>> API_NAMES["jack"] == rtmidi.API_UNIX_JACK
True
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import rtmidi

from sonibus.bus.errors import ConfigError

API_NAMES: dict[str, int] = {
    "auto": rtmidi.API_UNSPECIFIED, "jack": rtmidi.API_UNIX_JACK, "alsa": rtmidi.API_LINUX_ALSA,
    "coreaudio": rtmidi.API_MACOSX_CORE, "windows": rtmidi.API_WINDOWS_MM,
}
APIS = tuple(API_NAMES)


def _api(api: str) -> int:
    number = API_NAMES[api]
    if number != rtmidi.API_UNSPECIFIED and number not in rtmidi.get_compiled_api():
        compiled = [k for k, v in API_NAMES.items() if v in rtmidi.get_compiled_api()]
        raise ConfigError(f"key 'api': '{api}' is not built into python-rtmidi here — use one of: "
                          f"auto, {', '.join(compiled)}")
    return number


def _client(kind: type, api: str, client: str) -> Any:
    try:
        return kind(_api(api), client)
    except rtmidi.SystemError as exc:
        raise ConfigError(f"key 'api': cannot reach the MIDI system '{api}': {exc} "
                          f"(JACK: is jackd running? ALSA: is /dev/snd/seq there?)") from None


def find_port(names: list[str], wanted: str) -> int | None:
    """The index of the port named ``wanted``, else of the first one containing it (case-insensitive).

    >>> find_port(["a:sonibus 1", "synth:in 2"], "synth")
    1
    >>> find_port(["x", "y"], "z") is None
    True
    """
    if wanted in names:
        return names.index(wanted)
    matches = [i for i, n in enumerate(names) if wanted.lower() in n.lower()]
    return matches[0] if matches else None


def _open(port: Any, kind: str, api: str, name: str, connect: str) -> Any:
    if connect:
        names = port.get_ports()
        index = find_port(names, connect)
        if index is None:
            port.delete()
            raise ConfigError(f"key 'connect': no MIDI {kind} port matches '{connect}' (api {api}) — available: "
                              f"{', '.join(repr(n) for n in names) or 'none'}")
        port.open_port(index, name)
    else:
        try:
            port.open_virtual_port(name)
        except (rtmidi.UnsupportedOperationError, NotImplementedError, rtmidi.SystemError) as exc:
            port.delete()
            raise ConfigError(f"key 'port': cannot create virtual port '{name}' ({exc}); on Windows "
                              f"create it with loopMIDI and use connect = \"{name}\"") from None
    return port


def open_output(api: str, port: str, connect: str, client: str = "sonibus") -> Any:
    """An open ``rtmidi.MidiOut``: the virtual port ``port``, or the existing port matching ``connect``."""
    return _open(_client(rtmidi.MidiOut, api, client), "output", api, port, connect)


def open_input(api: str, port: str, connect: str, callback: Callable[[Any, Any], None],
               client: str = "sonibus") -> Any:
    """An open ``rtmidi.MidiIn`` calling ``callback((message, delta), None)`` on rtmidi's thread."""
    midi_in = _open(_client(rtmidi.MidiIn, api, client), "input", api, port, connect)
    midi_in.ignore_types(sysex=True, timing=True, active_sense=True)
    midi_in.set_callback(callback)
    return midi_in


def close(port: Any) -> None:
    """Close and free an rtmidi port (safe twice)."""
    try:
        port.close_port()
        port.delete()
    except Exception:  # already deleted
        pass


class Closer:
    """Closes an rtmidi port when the adapter stops (given to ``own``: after the workers are joined)."""

    def __init__(self, port: Any) -> None:
        self.port = port

    def close(self) -> None:
        close(self.port)
