"""Options of the ``jack`` adapter.

    [nodes.jack]
    adapter = "jack"
    robot = "pepper"
    inputs = ["left", "right"]                 # sonibus:left, sonibus:right → pepper/audio/speaker
    connect_inputs = ["pd:output_1", "pd:output_2"]

>>> JackConfig(inputs=3).input_names
('speaker_1', 'speaker_2', 'speaker_3')
>>> JackConfig(outputs=("l", "r"), connect_outputs=("pd:input_1",)).output_names
('l', 'r')
>>> JackConfig(inputs=("a", "a"))
Traceback (most recent call last):
...
sonibus.bus.errors.ConfigError: key 'inputs': port 'a' is named twice
"""

from __future__ import annotations

from dataclasses import dataclass

from sonibus.bus import keys
from sonibus.bus.options import bad

MAX_PORTS = 8           # the audio contract's channel limit
MAX_CHUNK_MS = 100.0    # the audio contract's longest chunk


def port_names(key: str, value: int | tuple[str, ...], prefix: str) -> tuple[str, ...]:
    """``value`` (a count, or names) as port names: ``3`` → ``prefix_1`` .. ``prefix_3``."""
    if isinstance(value, int):
        if not 0 <= value <= MAX_PORTS:
            raise bad(key, f"{value} must be in 0..{MAX_PORTS}")
        return tuple(f"{prefix}_{i}" for i in range(1, value + 1))
    if len(value) > MAX_PORTS:
        raise bad(key, f"{len(value)} ports, at most {MAX_PORTS} (the channels of one audio chunk)")
    for name in value:
        if not name or ":" in name:
            raise bad(key, f"port name {name!r} must be non-empty and without ':' (the client's name is added)")
        if value.count(name) > 1:
            raise bad(key, f"port '{name}' is named twice")
    return value


@dataclass(frozen=True)
class JackConfig:
    robot: str = "pepper"
    server: str = ""                             # JACK server name; "": $JACK_DEFAULT_SERVER, else "default"
    client_name: str = "sonibus"
    to_robot: bool = True                        # input ports → <robot>/audio/speaker
    from_robot: bool = True                      # <robot>/audio/mic → output ports
    inputs: int | tuple[str, ...] = 2            # a count (speaker_1, speaker_2, ...) or the ports' names
    outputs: int | tuple[str, ...] = 2           # a count (mic_1, mic_2, ...) or the ports' names
    connect_inputs: tuple[str, ...] = ()         # ports played into our inputs, in order ("pd:output_1")
    connect_outputs: tuple[str, ...] = ()        # ports our outputs play into, in order ("pd:input_1")
    chunk_ms: float = 10.0                       # length of a published chunk
    target_ms: float = 60.0                      # jitter buffer of the output side
    send_silence: bool = False                   # false: digital silence is not sent (the robot's speaker idles)
    queue: int = 256                             # chunks from the bus waiting for the jitter buffer

    def __post_init__(self) -> None:
        try:
            keys.check_name("robot", self.robot)
        except ValueError as exc:
            raise bad("robot", str(exc)) from None
        if not self.client_name or ":" in self.client_name:
            raise bad("client_name", f"{self.client_name!r} must be non-empty and without ':'")
        if not self.to_robot and not self.from_robot:
            raise bad("to_robot", "and from_robot are both false: the node would do nothing — set one to true")
        for key, names, connect in (("inputs", self.input_names, self.connect_inputs),
                                    ("outputs", self.output_names, self.connect_outputs)):
            if len(connect) > len(names):
                raise bad(f"connect_{key}", f"{len(connect)} ports for {len(names)} {key} — one port per "
                                            f"{key[:-1]}, in order; add {key} or connect fewer")
        if self.to_robot and not self.input_names:
            raise bad("inputs", "is 0 while to_robot is true — give at least one input port")
        if self.from_robot and not self.output_names:
            raise bad("outputs", "is 0 while from_robot is true — give at least one output port")
        if not 1.0 <= self.chunk_ms <= MAX_CHUNK_MS:
            raise bad("chunk_ms", f"{self.chunk_ms:g} must be in 1..{MAX_CHUNK_MS:g} (ms; 10-20 is usual)")
        if not 0 < self.target_ms <= 2000:
            raise bad("target_ms", f"{self.target_ms:g} must be more than 0 and at most 2000 (ms)")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def input_names(self) -> tuple[str, ...]:
        return port_names("inputs", self.inputs, "speaker")

    @property
    def output_names(self) -> tuple[str, ...]:
        return port_names("outputs", self.outputs, "mic")
