"""Values nobody LISTENs to cost nothing per frame (issue 35): the node keeps each robot's
latest frame as it came and takes it apart into values only when a client asks for one,
and then the answer is the latest frame's."""

from __future__ import annotations

from ..conftest import wait_for


def test_frames_nobody_listens_to_are_taken_apart_only_when_a_value_is_asked_for(served):
    live, stats = served.node.live, served.node.stats
    before, received = live.taken_apart, stats["received"]
    wait_for(lambda: stats["received"] >= received + 25, 10, "half a second of frames received")
    assert live.taken_apart == before, f"{live.taken_apart - before} frames taken apart with nobody asking"
    first = served.json("/pepper/joints/HeadYaw?VALUE")["VALUE"]
    assert live.taken_apart == before + 1  # the latest frame, once
    assert served.json("/pepper/joints/HeadYaw?VALUE")["VALUE"] == first or live.taken_apart == before + 2
    received = stats["received"]
    wait_for(lambda: stats["received"] >= received + 5, 10, "more frames")
    wait_for(lambda: served.json("/pepper/joints/HeadYaw?VALUE")["VALUE"] != first, 10,
             "the value asked for again: a later frame's (the idle robot moves)")
