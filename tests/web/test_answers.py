"""Issue 26, items 5 and 6: a page hears about every command it sent — a reply, a
refusal, or "dropped: too many at once", never nothing — and NaN or Infinity where
JSON enters is refused, never held as a slider move nor answered ``coalesced``."""

from __future__ import annotations

import json

import pytest

from sonibus.adapters.web import server
from sonibus.bus.commands import from_json
from sonibus.bus.errors import CommandError

from ..conftest import wait_for
from .conftest import Socket


def burst(page: Socket, messages: list[dict | str]) -> None:
    """Send ``messages`` (objects, or JSON text as it is) back to back from the page's loop."""
    async def send() -> None:
        for message in messages:
            await page._ws.send_str(message if isinstance(message, str) else json.dumps(message))
    page._run(send(), timeout=60)


def replies(page: Socket, ids: set) -> list[dict]:
    return [m for m in page.texts() if m.get("type") == "reply" and m.get("id") in ids]


@pytest.mark.parametrize("count", [200, 1000])
def test_every_command_of_a_burst_is_answered_or_said_dropped(stage, websocket, figure, count):
    """The issue's 200 (and 1,000) valid commands at once from a page that reads: 65 (741)
    replies never reached it, pushed out of its backlog by frames and events."""
    page = websocket(stage.ws_url())
    page.wait("hello")
    ids = set(range(count))
    burst(page, [{"type": "command", "id": i, "robot": "pepper", "verb": "behavior/list"} for i in ids])
    got = wait_for(lambda: len(replies(page, ids)) >= count and replies(page, ids), 60, f"{count} replies",
                   lambda: f"{len(replies(page, ids))} of {count} replies")
    assert sorted(r["id"] for r in got) == sorted(ids), "a command answered twice or not at all"
    dropped = [r for r in got if not r["ok"]]
    assert all(r["error"].startswith("dropped: too many at once") for r in dropped), dropped[:3]
    assert stage.node.stats["commands_dropped"] == len(dropped)
    figure(f"{count} commands at once: answered ok", count - len(dropped), f"(dropped, said so: {len(dropped)}; "
                                                                        "lost: 0)")
    if count <= server.MAX_ASKING:
        assert not dropped


def test_nan_and_infinity_from_a_page_are_refused_never_coalesced(stage, websocket):
    """A NaN move held as a slider move was answered ``{"ok": true, "result": {"coalesced": true}}``
    once a later move replaced it."""
    page = websocket(stage.ws_url())
    page.wait("hello")

    def move(id_: int, angle: str) -> str:
        return ('{"type": "command", "id": ' + str(id_) + ', "robot": "pepper", "verb": "joints/set", '
                '"args": {"names": ["HeadYaw"], "angles": [' + angle + ']}}')
    for i, bad in enumerate(("NaN", "Infinity", "-Infinity")):
        # a move sent at once, the bad one held behind it (slider_hz), a later one that supersedes it
        burst(page, [move(10 * i, "0.1"), move(10 * i + 1, bad), move(10 * i + 2, "0.2")])
        refused = page.wait("reply", id=10 * i + 1)
        assert refused["ok"] is False and f"{bad} is not a JSON number" in refused["error"], refused
        assert page.wait("reply", id=10 * i + 2)["ok"] is True
    assert stage.node.stats["bad"] == 3


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_from_json_refuses_what_is_not_a_finite_number(value):
    with pytest.raises(CommandError) as refused:
        from_json("joints/set", {"names": ["HeadYaw"], "angles": [value]})
    assert refused.value.code == "bad_request" and "must be a finite number" in refused.value.message
    with pytest.raises(CommandError):
        from_json("posture", {"name": "Stand", "speed": value})
