"""Skip, never burst: a loop on absolute deadlines (``Pacer``, where frames are made)
and the spacing of frames where they arrive (``Spacing``, where sinks send them).

>>> import threading
>>> stop, seen = threading.Event(), []
>>> def tick(frame: int) -> None:
...     seen.append(frame)
...     if len(seen) == 3:
...         stop.set()
>>> skipped = Pacer(200.0).run(tick, stop)
>>> seen[0], len(seen), seen == sorted(set(seen))  # in order; a late tick shows as a jump in frame
(0, 3, True)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import NamedTuple

from .capped import Capped

SHARE = 0.75          # after a stall, a stream's frames go no closer than this share of its period
STALL_PERIODS = 2.0   # a stall: no frame of a stream for this many of its periods,
STALL_S = 0.25        # and for this long: a shorter gap is a busy machine's scheduling (its backlog is
                      # a few frames, taken together by a worker), which spacing would only thin out
MAX_GAP_S = 0.05      # a frame is never held longer (well under a sink's max_age_ms: what is held stays fresh)
MAX_PERIOD_S = 1.0    # a longer spacing is a pause or a clock's jump, not a stream's period
RESTART_S = 0.25      # a frame this much older than the last one sent starts the stream over (a clock set
                      # back, or a sample put on its key with a t ahead: it holds the stream back no longer)
SLACK_S = 0.002       # a frame less early than this goes (Zenoh batches what is put within a millisecond)
LEARNING = 3          # frames whose spacing teaches a stream's period before it is paced (a script's few are not)
MAX_STREAMS = 10_000  # streams remembered (their names come from the network)
MAX_BYTES = 4 << 20  # bytes of them (a key may be tens of KB long)
_STREAM = 300        # bytes of one stream's state beside its key

class Pacer:
    """Calls ``tick(frame)`` at ``rate_hz`` against deadlines fixed at the start.

    A tick that comes back late by more than a period (a slow robot, a VM
    stall) makes the loop skip the frames it missed: ``frame`` jumps, so the
    gap shows in ``seq``, and no frame is ever sent twice as fast to catch up."""

    def __init__(self, rate_hz: float) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate {rate_hz} Hz must be more than 0")
        self.period = 1.0 / rate_hz
        self.skipped = 0

    def run(self, tick: Callable[[int], None], stop: threading.Event) -> int:
        """Loop until ``stop`` is set; returns the number of frames skipped."""
        start = time.monotonic()
        frame = 0
        while not stop.is_set():
            tick(frame)
            frame += 1
            late = time.monotonic() - (start + frame * self.period)
            if late > self.period:
                missed = int(late / self.period)
                frame += missed
                self.skipped += missed
            stop.wait(max(0.0, start + frame * self.period - time.monotonic()))
        return self.skipped


class Turn(NamedTuple):
    """What ``Spacing.turn`` says of a frame: ``go`` now, else hold it ``until`` then
    (a newer frame of the stream replaces it), or skip it (``until`` is 0: a newer
    frame went already)."""

    go: bool
    until: float = 0.0


GO = Turn(True)
SKIP = Turn(False)


class _Stream:
    """What ``Spacing`` knows of one stream."""

    __slots__ = ("arrived", "learnt", "period", "recovering", "seen_seq", "seen_t", "sent_at", "sent_t")

    def __init__(self, t: float, seq: int, now: float) -> None:
        self.period, self.learnt = 0.0, 0     # its period, learnt from how many spacings
        self.seen_t, self.seen_seq = t, seq   # the newest frame seen
        self.arrived = now                    # when the last frame arrived (monotonic)
        self.sent_at, self.sent_t = now, t    # when the last frame went, and its t
        self.recovering = False               # after a stall, until its frames arrive at their pace again


class Spacing:
    """Skip, never burst, where frames arrive: after a stall a stream's frames go no
    closer than ``SHARE`` of its own period.

    A stall (a link cut and healed, a paused process, a full queue) holds a stream's
    frames back; then they arrive together, and sent as they come they would replay
    the stall as a burst. Here, once no frame came for ``STALL_PERIODS`` periods (and
    ``STALL_S`` at least: a worker late by a few frames on a busy machine is no stall), the
    first goes, the next is held until its turn and each newer one replaces it: the
    newest goes most of a period later, the ones between are skipped, and no frame
    goes out older than one already sent. Once frames arrive at their pace again,
    they go as they come: jitter outside a stall holds nothing back. The period is
    learnt from the frames' own ``t`` and ``seq`` (from the ``LEARNING``-th frame on).
    Safe from any thread.

    >>> spacing = Spacing()
    >>> [spacing.turn("pepper/frame", 0.01 * n, n, now=0.01 * n) for n in range(5)][-1]  # 100 Hz, on time
    Turn(go=True, until=0.0)
    >>> spacing.turn("pepper/frame", 0.05, 5, now=0.5)         # after a stall: goes
    Turn(go=True, until=0.0)
    >>> spacing.turn("pepper/frame", 0.06, 6, now=0.5005)      # 0.5 ms later: a burst, held
    Turn(go=False, until=0.5075)
    >>> spacing.turn("pepper/frame", 0.045, 4, now=0.501)      # older than one sent: skipped
    Turn(go=False, until=0.0)
    """

    def __init__(self, share: float = SHARE) -> None:
        self.share = share
        self._streams: Capped[str, _Stream] = Capped(MAX_STREAMS, MAX_BYTES)  # (their keys: capped by bytes too)
        self._lock = threading.Lock()

    def turn(self, stream: str, t: float, seq: int, now: float | None = None, arrived: bool = True) -> Turn:
        """Whether a frame of ``stream`` (its ``t`` and ``seq``) goes ``now`` (``time.monotonic()``;
        it is then noted as sent), waits, or is skipped. ``arrived``: False for a frame that
        waited and whose turn came (its arrival was counted when it came)."""
        now = time.monotonic() if now is None else now
        with self._lock:
            state = self._streams.get(stream)
            if state is None or t < state.sent_t - RESTART_S:  # a new stream, or one whose clock went back
                self._streams.put(stream, _Stream(t, seq, now), len(stream) + _STREAM)
                return GO
            paced, gap, stalled = state.learnt >= LEARNING, 0.0, False
            if arrived:
                # the period, from the frames' own clock (a skipped seq counts); inline: a call a frame less
                if seq > state.seen_seq and t > state.seen_t:
                    sample = (t - state.seen_t) / (seq - state.seen_seq)
                    if sample <= MAX_PERIOD_S:
                        state.period = sample if not state.period else state.period + (sample - state.period) / 8
                        state.learnt += 1
                    state.seen_t, state.seen_seq = t, seq
                gap, state.arrived = now - state.arrived, now
                stalled = paced and gap >= max(STALL_PERIODS * state.period, STALL_S)
                state.recovering = state.recovering or stalled
            if t < state.sent_t or (t == state.sent_t and paced):  # (a script may put one sample again)
                return SKIP
            if state.recovering:
                # (nor closer than they were made: a source that makes frames fast is not held)
                due = state.sent_at + min(self.share * min(state.period, t - state.sent_t), MAX_GAP_S)
                if now < due - SLACK_S:
                    return Turn(False, due)
                if arrived and not stalled and gap >= self.share * state.period - SLACK_S:
                    state.recovering = False  # (its frames arrive at their pace again)
            state.sent_at, state.sent_t = now, t
            return GO
