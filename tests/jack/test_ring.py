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


class PreemptedWrite(np.ndarray):
    """The ring's storage, whose writer is preempted right after it copied the wrapped
    part of its block, before it advanced its counter: the reader runs then."""

    reader: object

    def __setitem__(self, index, value):  # type: ignore[no-untyped-def]
        super().__setitem__(index, value)
        reader = getattr(self, "reader", None)
        if reader is not None and isinstance(index, tuple) and index[0].start is None:
            self.reader = None
            reader()


def test_a_chunk_the_writer_is_still_overwriting_is_lost_whole_not_torn():
    ring = FrameRing(channels=1, rate=1000, capacity=16)
    ring.write([np.arange(6, dtype=np.float32)], t=100.0)
    data = ring._data.view(PreemptedWrite)
    read: list[object] = []
    data.reader = lambda: read.append(ring.read(4))
    ring._data = data
    ring.write([np.full(12, 9.0, np.float32)], t=100.006)      # frames 6..17: slots 6..15, then 0 and 1
    assert read == [None] and ring.lost == 4                  # frames 0..3 were half overwritten
    t, chunk = ring.read(4)
    assert chunk[:, 0].tolist() == [9.0, 9.0, 9.0, 9.0] and t == 100.008 and ring.lost == 8  # (4..7 too near)
