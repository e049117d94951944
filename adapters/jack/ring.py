"""``FrameRing``: audio frames from JACK's process callback to a worker, without a lock.

One writer (the real-time callback) says how far the block it copies in will
reach (``writing``), copies it into a preallocated array and then advances a
counter (``written``); one reader cuts what is there into chunks.
Only the writer changes ``writing``, ``written`` and ``offset``, only the reader ``read``
(a Python assignment is atomic), so neither ever waits for the other. A
reader that falls more than the ring behind loses the oldest frames, whole
chunks of them (counted in ``lost``), and goes on from what is still there;
a chunk the writer overwrote while it was being copied is lost the same way,
never handed on torn (also when the writer was still in the middle of its block:
``writing`` says so before ``written`` does).

Times: the callback reads the clock late by however long JACK took to call
it, so the wall clock of frame ``n`` is ``offset + n / rate``, ``offset`` the
least (clock − n / rate) seen, let rise by ``DRIFT`` to follow a JACK clock
slower than the wall clock (a sound card's by 0.01 %, the dummy driver's by 5 %
and more on a busy machine): chunks' ``t`` are steady, without the callback's
jitter, and do not fall behind.

>>> import numpy as np
>>> ring = FrameRing(channels=2, rate=1000, capacity=8)
>>> ring.write([np.arange(4, dtype=np.float32), -np.arange(4, dtype=np.float32)], t=100.0)
>>> ring.read(3)
(100.0, array([[ 0., -0.],
       [ 1., -1.],
       [ 2., -2.]], dtype=float32))
>>> ring.read(3) is None                         # one frame waits for two more
True
>>> ring.write([np.zeros(6, np.float32)] * 2, t=100.007)    # called 3 ms late
>>> ring.read(3)[0], ring.lost   # 10 written, 3 read: a chunk skipped; t by the clock (+ DRIFT), not 3 ms late
(100.0075, 3)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

DRIFT = 0.25  # s per s the offset may rise: beyond the dummy driver's lag (5-10 %), far beyond a sound card's


class FrameRing:
    """Float32 frames in (``write``, real-time safe), fixed-size chunks out (``read``)."""

    def __init__(self, channels: int, rate: int, capacity: int) -> None:
        self.rate = rate
        self.capacity = capacity
        self.lost = 0                 # frames overwritten before they were read
        self._data = np.zeros((capacity, channels), np.float32)
        self._written = 0             # frames ever written (writer only)
        self._writing = 0             # frames written once the block being copied in is (writer only)
        self._read = 0                # frames ever read (reader only)
        self._offset = math.inf       # wall-clock s of frame 0 (writer only)

    def write(self, columns: Sequence[np.ndarray], t: float) -> None:
        """One block, a column per channel, whose first frame was taken at ``t`` (wall clock)."""
        n = len(columns[0])
        self._writing = self._written + n  # first: a reader sees which frames may be changing under it
        start = self._written % self.capacity
        first = min(n, self.capacity - start)
        for channel, column in enumerate(columns):
            self._data[start:start + first, channel] = column[:first]
            if first < n:
                self._data[:n - first, channel] = column[first:n]
        self._offset = min(self._offset + DRIFT * n / self.rate, t - self._written / self.rate)
        self._written += n  # last: the reader sees the frames only once they are there

    def read(self, frames: int) -> tuple[float, np.ndarray] | None:
        """The next ``frames`` frames and the wall-clock time of the first, or None until written."""
        written = self._written
        excess = written - self._read - (self.capacity - frames)
        if excess > 0:  # the writer is about to overwrite them: skip whole chunks (a reader sees a gap)
            skip = -(-excess // frames) * frames
            self.lost += skip
            self._read += skip
        if written - self._read < frames:
            return None
        index = np.arange(self._read, self._read + frames) % self.capacity
        chunk = self._data[index]
        t = round(self._offset + self._read / self.rate, 6)
        self._read += frames
        if self._writing > self._read - frames + self.capacity:  # lapped during the copy (or being): part is newer
            self.lost += frames
            return None
        return t, chunk
