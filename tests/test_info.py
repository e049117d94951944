"""Robot info asked for over the bus (``bus/info.py``): an owner claims its robot before it
serves its info (it is still connecting), so an unanswered robot is asked again soon."""

from __future__ import annotations

import sys
import threading
import time

from sonibus.bus import encode, keys
from sonibus.bus.info import UNANSWERED_RETRY_S, InfoRequests
from sonibus.bus.messages import Limits

from .conftest import wait_for


def test_a_robot_that_answered_nothing_is_asked_again_soon_not_after_the_full_retry(net):
    """A page showed a robot's frames 2.7 s before its controls: its first ask came before the
    owner served its info, and the next one only retry_s later."""
    watcher = net.bus("watcher")
    answers: list[dict] = []
    requests = InfoRequests(watcher, lambda robot, info: answers.append(info), lambda robot, text: None,
                            retry_s=30.0)
    asked = time.monotonic()
    requests.ask("pepper")                                     # nobody serves pepper/info yet
    net.sim("pepper")

    def ask_again() -> bool:
        requests.ask("pepper")                                 # what a node's refresh loop does
        return bool(answers)
    wait_for(ask_again, timeout=10, what="the info, asked again well before retry_s (30 s)")
    assert answers[0]["model"] == "pepper" and time.monotonic() - asked < 10


def test_a_robot_whose_info_is_unusable_waits_the_full_retry(net):
    owner, watcher = net.bus("owner"), net.bus("watcher")
    errors: list[str] = []
    requests = InfoRequests(watcher, lambda robot, info: None, lambda robot, text: errors.append(text), retry_s=30.0)
    served = owner.serve(keys.info("liar"), lambda q: q.reply(keys.info("liar"), encode({"robot": "liar"})))
    try:
        # (asked until it answers: a queryable just declared may take a moment to reach the watcher)
        wait_for(lambda: requests.ask("liar") or errors, what="the unusable info said")
        deadline = time.monotonic() + 4 * UNANSWERED_RETRY_S
        while time.monotonic() < deadline:                     # (an absence: asked often, never sent again)
            requests.ask("liar")
            time.sleep(UNANSWERED_RETRY_S / 5)
    finally:
        served.undeclare()
    assert len(errors) == 1, errors


def derived_info(robot: str, alone: bool) -> dict:
    return {"robot": robot, "processor": {"host": "h", "node": "n"}, **({"alone": True} if alone else {}),
            "derived": [{"name": "map/head", "key": f"{robot}/derived/map/head", "unit": "cc", "size": 1,
                         "min": 0, "max": 127}]}


def test_a_source_that_is_no_robot_is_described_by_its_derived_info_alone_only_when_it_says_so(net):
    """A map node's info/derived says "alone": taken without an owner's info, by those who ask so. A
    features node's, for a robot whose owner serves no info yet, is not: that robot is no robot with no joints."""
    node, watcher = net.bus("node"), net.bus("watcher")
    answers: dict[str, dict] = {}
    served = [node.serve(keys.derived_info(name), lambda q, name=name, alone=alone: q.reply(
        keys.derived_info(name), encode(derived_info(name, alone)))) for name, alone in (("sound", True),
                                                                                        ("pepper", False))]
    alone = InfoRequests(watcher, lambda robot, info: answers.setdefault(robot, info), lambda robot, text: None,
                         retry_s=0.5, derived_alone=True)
    robots_only = InfoRequests(watcher, lambda robot, info: answers.setdefault(f"robots-only:{robot}", info),
                               lambda robot, text: None, retry_s=0.5)
    try:
        wait_for(lambda: alone.ask("sound") or robots_only.ask("sound") or "sound" in answers,
                 what="the map node's derived info, alone")
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:                     # (an absence: asked again and again)
            for requests in (alone, robots_only):
                requests.ask("pepper")
                requests.ask("sound")
            time.sleep(0.05)
    finally:
        for queryable in served:
            queryable.undeclare()
    assert answers["sound"] == {"joints": [], "derived": derived_info("sound", True)["derived"], "derived_alone": True}
    assert sorted(answers) == ["sound"], sorted(answers)


def test_asking_from_a_node_while_zenoh_counts_misses_takes_no_node_down():
    """``ask`` (a node's thread) made room among 1,024 made-up robots while Zenoh's threads
    counted queries nobody answered: "dictionary changed size during iteration" took the
    OSCQuery node, and with it ``sonibus run``, down in a fuzz campaign. Queries here end at
    once, unanswered, on threads of their own, as a thousand made-up robots' do."""
    class Bus:  # (what InfoRequests uses of a Bus: its limits, and ask)
        limits = Limits()

        def ask(self, selector, take, finish, timeout):
            threading.Thread(target=finish).start()

    failures: list[BaseException] = []
    requests = InfoRequests(Bus(), lambda robot, info: None, lambda robot, text: None, retry_s=0.001)

    def asking(first: int) -> None:
        try:
            for i in range(first, first + 3000):
                requests.ask(f"made-up{i % 1500}")
        except BaseException as exc:
            failures.append(exc)

    threads = [threading.Thread(target=asking, args=(n * 700,)) for n in range(3)]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # (threads taking turns as often as they can: the race, not the machine's luck)
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(60)
    finally:
        sys.setswitchinterval(interval)
    assert failures == []
