"""A robot's frames encoded with their names packed once (``codec.FrameEncoder``, issue 35)
are the very bytes ``codec.encode`` makes of the same map, and what a robot owner publishes
is unchanged on the wire: its frames' bytes are those of ``codec.encode`` of what they carry."""

from __future__ import annotations

import math
import random
import time

import pytest

from sonibus.bus import codec, messages

from .conftest import wait_for


def as_map(t: float, seq: int, names: list[str], values: list[float]) -> bytes:
    return codec.encode({"t": t, "seq": seq, "names": list(names), "v": list(values)})


@pytest.mark.parametrize("joints", [0, 1, 15, 16, 17, 26, 70000])
def test_a_frame_encoded_with_its_names_packed_once_is_byte_for_byte_the_map(joints):
    """Array headers (fix, 16-bit, 32-bit) and names short and long (fixstr, str8)."""
    rng = random.Random(joints)
    names = [("J" * rng.choice((1, 5, 31, 32, 40))) + str(j) for j in range(joints)]
    encoder = codec.FrameEncoder(names)
    for seq in (0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1):
        values = [rng.uniform(-10, 10) for _ in range(joints)]
        t = time.time() + rng.random()
        assert encoder.encode(t, seq, values) == as_map(t, seq, names, values), seq


@pytest.mark.parametrize(("t", "seq", "value"), [
    (1.0, 2**32, 0.5), (1.0, 2**64 - 1, 0.5), (1.0, -1, 0.5), (1.0, True, 0.5), (7, 3, 0.5),
    (1.5, 3, -0.0), (1.5, 3, 1e300), (1.5, 3, math.inf), (1.5, 3, math.nan)])
def test_an_unusual_time_sequence_number_or_float_is_packed_as_msgpack_packs_it(t, seq, value):
    """Outside the usual (``t`` a float, ``0 <= seq < 2**32``) the encoder packs the map itself;
    any float, even one the gate refuses, is packed to the same 9 bytes."""
    names = ["HeadYaw", "HeadPitch"]
    assert codec.FrameEncoder(names).encode(t, seq, [value, 0.25]) == as_map(t, seq, names, [value, 0.25])


def test_the_sims_frames_on_the_wire_are_the_bytes_of_the_map_they_carry(net):
    """A subscriber's payload is exactly ``codec.encode`` of what it decodes to: the sim
    (idle motion, every frame by the fast path) publishes what it published with msgpack."""
    net.sim(rate_hz=50, idle=True, body_sound=False, speaker=False)
    client = net.bus("client")
    _subscriber, queue = client.subscribe("pepper/frame", maxlen=1000)  # (kept: undeclared when dropped)
    payloads: list[bytes] = []

    def got() -> bool:
        while (item := queue.get(timeout=0)) is not None:
            payloads.append(bytes(item[1]))
        return len(payloads) >= 20

    wait_for(got, what="20 frames of the sim")
    seqs = set()
    for payload in payloads:
        frame = codec.decode(payload)
        assert list(frame) == list(messages.FRAME_FIELDS)
        assert codec.encode(frame) == payload
        seqs.add(frame["seq"])
    assert len(seqs) == len(payloads)
    moved = {tuple(codec.decode(p)["v"]) for p in payloads}
    assert len(moved) > 1, "idle motion: the values change from frame to frame"
