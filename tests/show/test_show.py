"""A show node driving a simulated robot over real Zenoh sessions: scenarios asked
for on the bus, what is refused and why, and the defined outcome of each failure —
a command refused, an end that never comes, the robot lost and back, an operator's
stop. What the robot executed is read from its owner's ``command`` events."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import pytest

from sonibus.adapters.show import Show, ShowConfig
from sonibus.adapters.show.clock import start
from sonibus.bus import client, codec
from sonibus.bus.errors import CommandError, OwnershipError

from ..conftest import wait_for
from ..test_commands import Rig, connect

YES = "animations/Stand/Gestures/Yes_1"    # 1.7 s in the simulator
HEY = "animations/Stand/Gestures/Hey_1"    # 3.1 s
SCENARIOS = {
    "hello": {"steps": [{"say": "Hello there"}, {"behavior": YES}, {"posture": "Stand"}, {"pause_s": 0.2}]},
    "wave": {"steps": [{"behavior": HEY}, {"say": "Bye"}]},
    "missing": {"steps": [{"say": "One"}, {"behavior": "animations/Not/There_1"}, {"say": "Two"}]},
    "hurried": {"steps": [{"behavior": HEY, "timeout_s": 0.3}, {"say": "Never said"}]},
}


def ask(rig: Rig, verb: str, args: dict[str, Any], timeout: float = 5.0) -> dict[str, Any] | CommandError:
    """A request to the robot's show, as the kiosk, the gateway and midi-in send it."""
    answered = threading.Event()
    outcome: list[Any] = []
    client.ask_program(rig.bus, rig.name, verb, args, lambda o: (outcome.append(o), answered.set()), timeout)
    assert answered.wait(timeout + 1)
    return outcome[0]


def commands(rig: Rig, since: int = 0) -> list[tuple[str, Any]]:
    """(verb, its main argument) of every command the owner executed, after the first ``since``."""
    found = rig.events.find("command")[since:]
    return [(c["verb"], c["args"].get("name", c["args"].get("text", c["args"].get("value")))) for c in found]


def start_show(net: Any, rig: Rig, name: str = "show", taken: bool = True, **options: Any) -> Show:
    """A show node for ``rig``'s robot; with ``taken``, once it took the robot (stop, stiffness, ready posture)."""
    show = Show(ShowConfig(robot=rig.name, scenarios=SCENARIOS, **options), name=name)
    net.start(show)
    if taken:
        wait_for(lambda: rig.events.find("posture", name=show.config.ready_posture, state="reached"), 10,
                 "the show to take the robot")
    return show


def scenario_events(rig: Rig, name: str) -> Callable[[], list[str]]:
    return lambda: [e["state"] for e in rig.events.find("scenario", name=name)]


def aborted(rig: Rig, name: str) -> dict[str, Any]:
    """The ``aborted`` event of scenario ``name``, waited for."""
    found = wait_for(lambda: rig.events.find("scenario", name=name, state="aborted"), 10, f"{name} aborted",
                     lambda: "\n".join(str(e) for e in rig.events.find() if e["kind"] != "motion"))
    return found[0]


def test_a_scenario_runs_its_steps_in_order_one_at_a_time_and_says_when_it_starts_and_ends(net):
    rig = connect(net)
    start_show(net, rig)
    assert commands(rig) == [("stop", None), ("stiffness", 1.0), ("posture", "StandInit")]
    assert ask(rig, "scenario", {"name": "hello", "by": "test"}) == {"name": "hello", "state": "accepted"}
    busy = ask(rig, "scenario", {"name": "wave"})
    assert isinstance(busy, CommandError) and busy.code == "busy" and "'hello' is under way" in busy.message
    wait_for(lambda: "ended" in scenario_events(rig, "hello")(), 15, "the scenario to end")
    assert commands(rig, 3) == [("say", "Hello there"), ("behavior/run", YES), ("posture", "Stand")]
    started, ended = rig.events.find("scenario", name="hello")
    assert (started["state"], started["by"], ended["state"]) == ("started", "test", "ended")
    said, behaved = rig.events.find("speech", state="done"), rig.events.find("behavior", state="stopped")
    assert said[0]["t"] <= behaved[0]["t"]  # each step waited for the previous one's end


def test_what_a_show_refuses_is_said_in_one_line_and_nothing_moves(net):
    rig = connect(net)
    show = start_show(net, rig)
    before = len(rig.events.find("command"))
    for verb, args, code, words in [
        ("scenario", {"name": "dance"}, "unknown_scenario", "no scenario 'dance' — scenarios: hello, wave"),
        ("scenario", {"name": "hello world"}, "bad_request", "name: 'hello world' does not match"),
        ("scenario", {"name": "hello", "loud": True}, "bad_request", "'loud' was unexpected"),
        ("scenario", {}, "bad_request", "'name' is a required property"),
        ("dance", {}, "unknown_verb", "a show takes scenario, status"),
    ]:
        refused = ask(rig, verb, args)
        assert isinstance(refused, CommandError) and (refused.code, words in refused.message) == (code, True), refused
    garbage = rig.bus.session.get("pepper/program/scenario", payload=b"\xc1\xff", timeout=5.0)
    answer = codec.decode(next(iter(garbage)).ok.payload)  # undecodable: refused in one line, the node stays up
    assert answer["error"]["code"] == "bad_request" and "scenario:" in answer["error"]["message"]
    status = ask(rig, "status", {})
    assert status["open"] and status["available"] and status["node"] == "show" and status["running"] == ""
    assert len(rig.events.find("command")) == before
    assert show.stats["requests_refused"] == 6 and show.stats["bad"] == 1 and show.state == "running"


def test_a_closed_show_rests_the_robot_with_stiffness_off_and_refuses_scenarios(net):
    rig = connect(net)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["tue-sun 10:00-18:00"],
                           scenarios=SCENARIOS), name="show")
    show.rehearse(1.0, start("2025-06-02 12:00", show.config.zone))  # a Monday
    net.start(show)
    wait_for(lambda: rig.events.find("command", verb="stiffness"), 10, "the robot put to rest")
    assert commands(rig) == [("stop", None), ("posture", "Crouch"), ("stiffness", 0.0)]
    closed = rig.events.find("show")[0]
    assert (closed["state"], closed["next"], closed["rehearsal"]) == ("closed", "2025-06-03T10:00:00+02:00", 1.0)
    refused = ask(rig, "scenario", {"name": "hello"})
    assert isinstance(refused, CommandError) and refused.code == "closed" and "opens Tue 10:00" in refused.message


def test_a_refused_step_aborts_its_scenario_with_the_reason_and_nothing_after_it_runs(net, caplog):
    rig = connect(net)
    start_show(net, rig)
    assert "behaviors of the show not on robot 'pepper': animations/Not/There_1 — its info lists 8" in caplog.text
    ask(rig, "scenario", {"name": "missing"})
    end = aborted(rig, "missing")
    assert end["step"] == 2 and "behavior/run refused: unknown behavior 'animations/Not/There_1'" in end["reason"]
    ask(rig, "scenario", {"name": "hello"})  # (the next command shows what came after the refusal: nothing)
    # (15 s: no bound of the show's, only the test's patience; a loaded CI timed out at 5 s once)
    wait_for(lambda: len(commands(rig, 3)) > 2, 15, "the next scenario's first command")
    assert commands(rig, 3)[:3] == [("say", "One"), ("behavior/run", "animations/Not/There_1"), ("say", "Hello there")]


def test_an_end_that_never_comes_aborts_at_the_steps_timeout_and_stops_what_may_still_run(net):
    rig = connect(net)
    start_show(net, rig)
    ask(rig, "scenario", {"name": "hurried"})
    end = aborted(rig, "hurried")
    assert (end["step"], end["reason"]) == (1, f"behavior {HEY}: no end heard within 0.3 s")
    wait_for(lambda: commands(rig, 3) == [("behavior/run", HEY), ("stop", None)], 5, "the stop after it")
    stop = rig.events.find("command", verb="stop")[-1]
    stopped = wait_for(lambda: rig.events.find("behavior", name=HEY, state="stopped"), 5, "the behavior's end")
    assert stopped[0]["t"] <= stop["t"]  # ended by that stop (the sim says so within it), not 3.1 s after its start
    assert ("say", "Never said") not in commands(rig)


def test_a_robot_lost_mid_scenario_aborts_it_and_once_back_is_stopped_and_made_ready_again(net):
    rig = connect(net)
    show = start_show(net, rig)
    ask(rig, "scenario", {"name": "wave"})
    wait_for(lambda: ("behavior/run", HEY) in commands(rig), 5, "the scenario's behavior")
    rig.sim.stop()  # its owner leaves the bus: its token goes at once
    end = aborted(rig, "wave")
    assert end["step"] == 1 and "robot 'pepper' lost" in end["reason"]
    refused = ask(rig, "scenario", {"name": "hello"})
    assert isinstance(refused, CommandError) and refused.code == "unavailable"
    before = len(rig.events.find("command"))
    net.sim("pepper", rate_hz=50, words_per_minute=600)  # back
    wait_for(lambda: commands(rig, before)[-1:] == [("posture", "StandInit")], 10, "the robot taken again")
    assert commands(rig, before) == [("stop", None), ("stiffness", 1.0), ("posture", "StandInit")]
    assert ("say", "Bye") not in commands(rig)  # nothing resumed half-way
    assert show.stats["aborted"] == 1


def test_an_operators_stop_ends_the_scenario_and_the_show_does_not_move_the_robot_again(net):
    rig = connect(net)
    start_show(net, rig)
    ask(rig, "scenario", {"name": "wave"})
    wait_for(lambda: ("behavior/run", HEY) in commands(rig), 5, "the scenario's behavior")
    client.send_command(rig.bus, "pepper", "stop")
    assert aborted(rig, "wave")["reason"] == "stopped by a stop command from elsewhere"
    assert commands(rig, 3) == [("behavior/run", HEY), ("stop", None)]  # the operator's, and nothing after


def test_a_second_show_for_the_same_robot_refuses_to_start_naming_the_first(net):
    rig = connect(net)
    start_show(net, rig)
    with pytest.raises(OwnershipError, match="robot 'pepper' already has a show: node 'show' on"):
        start_show(net, rig, name="show2", taken=False)


def test_a_scenario_accepted_just_before_closing_is_aborted_when_the_show_closes_behind_a_gesture(net):
    """Its gesture ends after closing time: the robot goes to rest, not into the scenario."""
    rig = connect(net)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["daily 10:00-10:01"],
                           idle={"behaviors": [HEY]}, scenarios=SCENARIOS), name="show")
    show.rehearse(10.0, start("2025-06-03 10:00:30", show.config.zone))  # the 3.1 s gesture spans 10:01
    net.start(show)
    wait_for(lambda: ("behavior/run", HEY) in commands(rig), 10, "the idle gesture")
    assert ask(rig, "scenario", {"name": "hello"}) == {"name": "hello", "state": "accepted"}
    assert aborted(rig, "hello")["reason"] == "the show closed before it started"
    wait_for(lambda: commands(rig)[-1:] == [("stiffness", 0.0)], 10, "the robot at rest")
    assert commands(rig)[-3:] == [("behavior/run", HEY), ("posture", "Crouch"), ("stiffness", 0.0)]
    refused = ask(rig, "scenario", {"name": "hello"})
    assert isinstance(refused, CommandError) and refused.code == "closed"
    assert scenario_events(rig, "hello")() == ["aborted"] and ask(rig, "status", {})["pending"] == ""
