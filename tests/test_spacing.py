"""``bus/pacing.Spacing`` under what the network may send on a stream's key: values
of ``t`` and ``seq`` made up, out of order, repeated, far ahead or behind. Whatever
came, once the stream's own samples flow again at their pace, every one of them goes
within ``RECOVERY_S`` (none held or skipped for good), and the table of streams stays
bounded however many keys are made up."""

from __future__ import annotations

import pytest

from sonibus.bus import pacing
from sonibus.bus.pacing import Spacing

PERIOD = 0.02   # a 50 Hz stream
T0 = 1.7e9      # its frames' clock (epoch seconds)
NOW0 = 1000.0   # the receiving host's monotonic clock
RECOVERY_S = 0.3  # a stream's own samples are skipped this long at most after made-up ones


def stream(spacing: Spacing, start: int, count: int, key: str = "pepper/derived/qom/Body",
           busy: int = 1) -> list[str]:
    """``count`` samples of the stream from its ``start``-th, each arriving on time
    (``busy`` > 1: taken ``busy`` at a time, as a consumer that fell behind by that many
    periods does); what each got: g(o), h(eld), s(kipped)."""
    out = []
    for n in range(start, start + count):
        now = NOW0 + (n - n % busy + busy - 1) * PERIOD
        turn = spacing.turn(key, T0 + n * PERIOD, n, now=now)
        out.append("g" if turn.go else ("h" if turn.until else "s"))
    return out


FUZZED = {  # what came on the stream's key, after its 50th sample (t as an offset from that sample's t)
    "t zero": [(-T0, 7)],
    "t a day back": [(-86400.0, 7)],
    "t 4 s ahead (within the gate's 5 s)": [(4.0, 10 ** 9)],
    "t 0.9 s ahead": [(0.9, 3)],
    "t a little ahead, seq far ahead": [(0.001 * i, 2 ** 62 + i) for i in range(100)],
    "the same sample again and again": [(0.0, 50)] * 500,
    "seq going back": [(0.001 * i, 1000 - i) for i in range(500)],
    "tiny steps of t and seq": [(i * 1e-9, 10 ** 6 + i) for i in range(2000)],
    "a period of a second": [(i * 0.9, 10 ** 6 + i) for i in range(5)],
}


@pytest.mark.parametrize("fuzz", FUZZED.values(), ids=FUZZED.keys())
def test_a_stream_recovers_from_made_up_t_and_seq(fuzz):
    spacing = Spacing()
    assert set(stream(spacing, 0, 50)) == {"g"}
    for offset, seq in fuzz:
        spacing.turn("pepper/derived/qom/Body", T0 + 50 * PERIOD + offset, seq, now=NOW0 + 50 * PERIOD)
    after = stream(spacing, 51, 100)
    recovered = int(RECOVERY_S / PERIOD)  # at most this many of its samples go to waste
    assert set(after[recovered:]) == {"g"}, "".join(after)


def test_a_consumer_that_falls_behind_a_little_is_not_thinned():
    """Samples taken two or three at a time (a busy machine's worker) all go: that is
    jitter, not a stall whose backlog would go out as a burst."""
    spacing = Spacing()
    stream(spacing, 0, 50)
    assert stream(spacing, 50, 150, busy=3).count("g") == 150


def test_after_a_stall_the_backlog_is_spaced():
    """The other side: a stall of a second (a link cut), then its frames at once: one
    goes, the newest of the rest is held, no two go within a period."""
    spacing = Spacing()
    stream(spacing, 0, 50)
    now = NOW0 + 100 * PERIOD  # a second without a frame
    turns = [spacing.turn("pepper/derived/qom/Body", T0 + n * PERIOD, n, now=now) for n in range(50, 100)]
    assert turns[0].go and not any(turn.go for turn in turns[1:])
    assert all(turn.until >= now + pacing.SHARE * PERIOD - 1e-6 for turn in turns[1:] if turn.until)


def test_made_up_streams_do_not_grow_the_table():
    spacing = Spacing()
    for n in range(pacing.MAX_STREAMS + 500):
        spacing.turn(f"robot{n}/frame", T0, 1, now=NOW0)
    assert len(spacing._streams) <= pacing.MAX_STREAMS
