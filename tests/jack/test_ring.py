"""``FrameRing`` (adapters/jack/ring.py) where the real-time writer and the reader meet."""

from __future__ import annotations

import numpy as np

from sonibus.adapters.jack.ring import FrameRing


class LappingData(np.ndarray):
    """The ring's storage, whose copy lets the writer run once in the middle (the
    process callback preempting the reader's thread)."""

    ring: FrameRing
    block: int

    def __getitem__(self, index):  # type: ignore[no-untyped-def]
        if isinstance(index, np.ndarray) and getattr(self, "ring", None) is not None:
            ring, self.ring = self.ring, None
            ring.write([np.full(self.block, 9.0, np.float32)], t=100.0 + ring._written / ring.rate)
        return np.asarray(super().__getitem__(index))


def test_a_chunk_overwritten_while_it_is_copied_is_lost_whole_not_torn():
    ring = FrameRing(channels=1, rate=1000, capacity=16)
    ring.write([np.arange(6, dtype=np.float32)], t=100.0)
    data = ring._data.view(LappingData)
    data.ring, data.block = ring, 14                          # the writer laps frames 0..3 during the copy
    ring._data = data
    assert ring.read(4) is None and ring.lost == 4
    t, chunk = ring.read(4)  # frames 4..7 are too near the writer now (20 written): skipped, whole
    assert chunk[:, 0].tolist() == [9.0, 9.0, 9.0, 9.0] and t == 100.008 and ring.lost == 8


def test_a_copy_the_writer_did_not_reach_is_handed_on():
    ring = FrameRing(channels=1, rate=1000, capacity=16)
    ring.write([np.arange(6, dtype=np.float32)], t=100.0)
    data = ring._data.view(LappingData)
    data.ring, data.block = ring, 2                           # writes past the end, not over the chunk
    ring._data = data
    t, chunk = ring.read(4)
    assert chunk[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0] and t == 100.0 and ring.lost == 0
