"""The kiosk's buttons (``adapters/web/kiosk.py``) against the order the robot's answers
and events may come in: a stop ends the running button, but a stop heard before the
robot answered the press was run by the robot before it and ends nothing."""

from __future__ import annotations

from sonibus.adapters.web.config import Button, Kiosk
from sonibus.adapters.web.kiosk import Stand
from sonibus.bus.errors import CommandError

SAY = Button("hello", "Say hello", say="Hello, visitors!")
STORY = Button("story", "A story", scenario="story")
STOPPED = {"t": 1.0, "kind": "command", "verb": "stop", "args": {}, "ok": True}


def stand() -> tuple[Stand, list[str]]:
    states: list[str] = []
    return Stand(Kiosk("pepper", (SAY,)), lambda m: states.append(m["state"])), states


def test_a_stop_after_the_robot_took_the_press_ends_the_button():
    kiosk, states = stand()
    kiosk.press(SAY)
    kiosk.answered(SAY, {"duration": 1.8, "queued": 1})
    kiosk.event("nao", "command", STOPPED)  # another robot's stop: not this kiosk's
    assert states == ["running"]
    kiosk.event("pepper", "command", {**STOPPED, "ok": False, "error": "refused"})
    assert states == ["running"] and kiosk.busy()
    kiosk.event("pepper", "command", STOPPED)
    assert states == ["running", "done"] and not kiosk.busy()


def test_a_stop_heard_before_the_robot_answered_the_press_ends_nothing():
    kiosk, states = stand()
    kiosk.press(SAY)
    kiosk.event("pepper", "command", STOPPED)
    kiosk.answered(SAY, {"duration": 1.8, "queued": 0})
    assert states == ["running"] and kiosk.busy()
    kiosk.event("pepper", "speech", {"t": 2.0, "kind": "speech", "text": SAY.say, "state": "done"})
    assert states == ["running", "done"]


def test_a_button_whose_end_never_comes_fails_at_its_timeout_and_frees_the_kiosk():
    kiosk, states = stand()
    first = kiosk.press(SAY)
    kiosk.answered(SAY, {"duration": 1.8, "queued": 0})
    assert not kiosk.overdue(first - 1), "an earlier press's timer ends nothing"
    assert kiosk.overdue(first) and states == ["running", "failed"] and not kiosk.busy()
    assert "within 120 s" in kiosk.states["hello"]["error"]
    second = kiosk.press(SAY)
    kiosk.answered(SAY, {"duration": 1.8, "queued": 0})
    kiosk.event("pepper", "speech", {"t": 2.0, "kind": "speech", "text": SAY.say, "state": "done"})
    assert not kiosk.overdue(second), "a press that ended in time is not failed later"
    assert states == ["running", "failed", "running", "done"]


def test_a_late_answer_to_a_press_that_timed_out_ends_nothing_of_the_next_press():
    kiosk, states = stand()
    first = kiosk.press(SAY)
    assert kiosk.overdue(first) and states == ["failed"]      # the robot did not answer within timeout_s
    second = kiosk.press(SAY)                                # the same button again
    kiosk.answered(SAY, CommandError("timeout", "no answer within 5 s"), first)  # the first press's, late
    assert states == ["failed"] and kiosk.busy(), "a late answer ended the press after it"
    kiosk.answered(SAY, {"duration": 1.8, "queued": 0}, second)
    assert states == ["failed", "running"] and kiosk.busy()


def scenario(state: str, **fields: object) -> dict[str, object]:
    return {"t": 2.0, "kind": "scenario", "name": "story", "state": state, "by": "kiosk", **fields}


def test_a_scenario_button_is_done_when_the_show_says_ended_and_failed_with_its_reason_when_aborted():
    assert STORY.command == ("scenario", {"name": "story", "by": "kiosk"})
    states: list[str] = []
    kiosk = Stand(Kiosk("pepper", (SAY, STORY)), lambda m: states.append(m["state"]))
    kiosk.press(STORY)
    kiosk.answered(STORY, {"name": "story", "state": "accepted"})
    kiosk.event("pepper", "scenario", scenario("started"))
    kiosk.event("pepper", "command", STOPPED)  # the show's own stops (a robot taken back) end nothing
    kiosk.event("pepper", "behavior", {"t": 2.0, "kind": "behavior", "name": "x", "state": "stopped"})
    assert states == ["running"] and kiosk.busy()
    kiosk.event("pepper", "scenario", scenario("ended"))
    assert states == ["running", "done"] and not kiosk.busy()
    kiosk.press(STORY)
    kiosk.answered(STORY, {"name": "story", "state": "accepted"})
    kiosk.event("pepper", "scenario", scenario("aborted", reason="robot 'pepper' lost (its owner left the bus)"))
    assert states == ["running", "done", "running", "failed"]
    assert kiosk.states["story"]["error"] == "robot 'pepper' lost (its owner left the bus)"


def test_the_shows_close_is_told_and_forgets_a_stale_done_and_a_press_is_refused_until_it_opens():
    """Issue 37, item 7: "closed, opens Tue 10:00", not the "done" of the last visitor."""
    said: list[dict] = []
    kiosk = Stand(Kiosk("pepper", (SAY,)), said.append)
    kiosk.event("pepper", "show", {"t": 1.0, "kind": "show", "state": "open", "next": "2025-06-03T18:00:00+02:00"})
    kiosk.press(SAY)
    kiosk.answered(SAY, {"duration": 1.8, "queued": 0})
    kiosk.event("pepper", "speech", {"t": 2.0, "kind": "speech", "text": SAY.say, "state": "done"})
    assert kiosk.states["hello"]["state"] == "done" and kiosk.closed() == ""
    kiosk.event("nao", "show", {"t": 3.0, "kind": "show", "state": "closed", "next": None})  # another robot's show
    assert kiosk.closed() == ""
    kiosk.event("pepper", "show", {"t": 3.0, "kind": "show", "state": "closed", "next": "2025-06-04T10:00:00+02:00"})
    assert said[-2:] == [{"type": "button", "id": "hello", "state": "idle"},
                         {"type": "show", "state": "closed", "next": "2025-06-04T10:00:00+02:00"}]
    assert kiosk.closed() == "closed, opens Wed 10:00" and kiosk.states["hello"]["state"] == "idle"
    kiosk.event("pepper", "show", {"t": 4.0, "kind": "show", "state": "closed", "next": "2025-06-04T10:00:00+02:00"})
    assert len(said) == 5  # (said again every announce_every_s: no news for the kiosks)
