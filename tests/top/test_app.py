"""``sonibus top``'s app driven by textual's pilot against a running simulator on a
private bus: joint values change on screen, a killed node turns red ("gone") within
the lease and stays listed, ``s`` then ``y`` halts every robot (checked on the bus),
``s`` then any other key sends nothing, tab selects the next robot, ``q`` quits."""

from __future__ import annotations

import re
import time

import pytest

from sonibus.adapters.show import Show, ShowConfig
from sonibus.adapters.show.clock import start
from sonibus.bus import decode, framing, keys, send_command
from sonibus.bus.cli.top import ALARM, WARNING

from ..conftest import SONIBUS
from .pilot import drive, row, shown, until
from .test_monitor import Lossy

BEHAVIOR = "animations/Stand/Gestures/Hey_1"


def joint_value(app, joint: str) -> str:
    found = re.search(rf"^{joint} .*?([+-]\d+\.\d{{3}})", shown(app, "joints"), re.MULTILINE)
    return found[1] if found else ""


def test_joint_values_change_on_screen(net, figure):
    net.sim("pepper", rate_hz=50, idle=True)  # breathing and looking around: its joints move on their own
    values: list[str] = []

    async def scenario(app, pilot):
        first = await until(pilot, lambda: joint_value(app, "HeadPitch"), what="HeadPitch on screen")
        values.append(first)
        values.append(await until(pilot, lambda: (v := joint_value(app, "HeadPitch")) != first and v,
                                  what="HeadPitch to change on screen"))
        assert shown(app, "joints").splitlines()[0].startswith("HeadYaw ")
        cells = await until(pilot, lambda: (r := row(app, "robots", "pepper")) and r[2].plain == "pepper" and r,
                            what="pepper's model in its row")
        assert [str(c) for c in cells][-1] == "connected"  # (its owner's state, bus/connection.py)
        started = time.perf_counter()
        for _ in range(20):
            app.redraw()
        took_ms = (time.perf_counter() - started) / 20 * 1000
        figure("one redraw (snapshot and widget updates; one robot, one node)", took_ms, "ms")

    drive(net.bus("top"), scenario)
    assert len(set(values)) == 2


def test_a_killed_node_turns_red_and_gone_within_the_lease_and_stays_listed(net, spawn, tmp_path, figure):
    show = tmp_path / "show.toml"
    show.write_text('[nodes.doomed]\nadapter = "sim"\nrobot = "nao"\nrate_hz = 20\n')
    process = spawn(SONIBUS, "run", str(show), *net.cli_args())
    top = net.bus("top")
    lease_s = top.lease_s
    nodes = f"{top.host}/doomed"

    async def scenario(app, pilot):
        await until(pilot, lambda: (r := row(app, "nodes", nodes)) and r[4].plain == "running"
                    and r[0].plain == "sim", timeout=20, what="the run's node listed, running, its adapter known")
        await until(pilot, lambda: (r := row(app, "robots", "nao")) and r[-1].plain == "connected",
                    what="its robot listed")
        process.kill()  # SIGKILL: no goodbye, only the lease tells
        killed = time.monotonic()
        cells = await until(pilot, lambda: (r := row(app, "nodes", nodes)) and r[4].plain == "gone" and r,
                            timeout=lease_s + 10, what="the killed node shown as gone")
        figure("a killed node shown gone after", time.monotonic() - killed, "s")
        figure("lease", lease_s, "s")
        assert all(str(c.style) == ALARM for c in cells), [c.style for c in cells]
        assert cells[0].plain == "sim" and cells[2].plain == "doomed"
        await until(pilot, lambda: row(app, "robots", "nao")[-1].plain == "gone", what="its robot shown gone")
        await pilot.pause(0.3)  # a few redraws later, both are still listed
        assert row(app, "nodes", nodes)[4].plain == "gone" and row(app, "robots", "nao") is not None

    drive(top, scenario)


def watch_events(net, robot: str) -> list[dict]:
    """The events of ``robot`` as a separate machine sees them."""
    seen: list[dict] = []
    watcher = net.bus("watcher")
    watcher.session.declare_subscriber(keys.event(robot, "*"), lambda s: seen.append(decode(s.payload.to_bytes())))
    return seen


def commands(seen: list[dict], verb: str) -> list[dict]:
    return [e for e in seen if e["kind"] == "command" and e["verb"] == verb]


async def ask_to_stop(app, pilot) -> None:
    """Press ``s`` and wait for the question."""
    await pilot.press("s")
    await until(pilot, lambda: "Stop every robot" in str(app.screen.query_one("Static").content),
                what="the confirmation")


def test_s_then_y_stops_every_robot_and_shows_each_reply(net):
    pepper, nao = net.sim("pepper", rate_hz=50), net.sim("nao", rate_hz=50)
    seen, heard_nao = watch_events(net, "pepper"), watch_events(net, "nao")
    top = net.bus("top")

    async def scenario(app, pilot):
        await until(pilot, lambda: row(app, "robots", "pepper") and row(app, "robots", "nao"), what="both robots")
        send_command(top, "pepper", "behavior/run", {"name": BEHAVIOR})
        await until(pilot, lambda: pepper.engine.running_behavior, what="the behavior running")
        await ask_to_stop(app, pilot)
        await pilot.press("y")
        await until(pilot, lambda: commands(seen, "stop") and commands(heard_nao, "stop"), what="both stop commands")
        lines = await until(pilot, lambda: (t := shown(app, "event-lines")).count("ok: stopped") == 2 and t,
                            what="both replies on screen")
        assert re.search(r"pepper +stop +ok: stopped", lines) and re.search(r"nao +stop +ok: stopped", lines)

    drive(top, scenario)
    assert commands(seen, "stop")[0]["ok"] is True and commands(heard_nao, "stop")[0]["ok"] is True
    stopped = [e for e in seen if e["kind"] == "behavior" and e["state"] == "stopped"]
    assert stopped and stopped[0]["name"] == BEHAVIOR
    assert pepper.engine.running_behavior is None and not pepper.body.moving() and not nao.body.moving()


def test_y_also_stops_a_robot_that_came_while_the_stop_was_asked(net):
    net.sim("pepper", rate_hz=50)
    heard_nao = watch_events(net, "nao")
    top = net.bus("top")

    async def scenario(app, pilot):
        await until(pilot, lambda: row(app, "robots", "pepper"), what="pepper listed")
        await ask_to_stop(app, pilot)
        net.sim("nao", rate_hz=50)  # (the operator reads the question; a robot joins the show)
        await until(pilot, lambda: (r := row(app, "robots", "nao")) and r[-1].plain == "connected", what="nao listed")
        await pilot.press("y")
        await until(pilot, lambda: commands(heard_nao, "stop"), what="nao's stop")

    drive(top, scenario)
    assert commands(heard_nao, "stop")[0]["ok"] is True


@pytest.mark.parametrize("key", ["n", "q", "tab", "escape"])
def test_s_then_another_key_sends_nothing(net, key):
    pepper = net.sim("pepper", rate_hz=50)
    seen = watch_events(net, "pepper")
    top = net.bus("top")

    async def scenario(app, pilot):
        await until(pilot, lambda: row(app, "robots", "pepper"), what="pepper listed")
        await ask_to_stop(app, pilot)
        await pilot.press(key)
        await until(pilot, lambda: "cancelled: nothing sent" in shown(app, "event-lines"), what="the cancel shown")
        assert app.screen is app.screen_stack[0] and app.is_running  # the confirmation is gone, the view goes on
        # A command after the cancel: once its event is here, a stop sent on the cancel would be too.
        send_command(top, "pepper", "behavior/list")
        await until(pilot, lambda: commands(seen, "behavior/list"), what="the later command's event")

    drive(top, scenario)
    assert commands(seen, "stop") == []
    assert pepper.stats["errors"] == 0


def test_tab_and_up_select_the_robot_and_q_quits_with_0(net):
    net.sim("pepper", rate_hz=20)
    net.sim("nao", rate_hz=20)

    async def scenario(app, pilot):
        await until(pilot, lambda: row(app, "robots", "pepper") and row(app, "robots", "nao"), what="both robots")
        title = str(app.query_one("#joints").border_title)
        await pilot.press("tab")
        await until(pilot, lambda: str(app.query_one("#joints").border_title) != title, what="the other robot")
        assert {title, str(app.query_one("#joints").border_title)} == {"joints of nao", "joints of pepper"}
        await pilot.press("up")
        await until(pilot, lambda: str(app.query_one("#joints").border_title) == title, what="the first robot again")
        await pilot.press("q")

    app = drive(net.bus("top"), scenario)
    assert app.return_value == 0


def test_ctrl_c_ends_it_as_an_interrupted_command(net):
    async def scenario(app, pilot):
        await pilot.press("ctrl+c")

    assert drive(net.bus("top"), scenario).return_value == 130


def test_a_loss_counter_that_moves_is_yellow_and_others_are_not(net):
    lossy = net.start(Lossy(name="lossy"))
    key = f"{lossy.bus.host}/lossy"

    async def scenario(app, pilot):
        cells = await until(pilot, lambda: (r := row(app, "nodes", key)) and r[7].plain != "0" and r,
                            what="lossy's drops on screen")
        dropped, stale, bad, errors = cells[7:]
        assert str(dropped.style) == WARNING and int(dropped.plain.replace(",", "")) > 0
        assert [str(c.style) for c in (stale, bad, errors)] == ["", "", ""] and cells[4].plain == "running"

    drive(net.bus("top"), scenario)


def test_a_robot_name_like_markup_is_shown_as_written(net):
    """Names are key chunks, and ``[`` is allowed in one: a title given as a str would be rich markup."""
    script = net.bus("script")

    async def scenario(app, pilot):
        def put() -> None:
            script.put(keys.frame("[b]bot"), framing.frame(time.time(), 1, ["HeadYaw"], [0.5]))

        await until(pilot, lambda: row(app, "robots", "[b]bot") or put(), what="the robot listed")
        await until(pilot, lambda: app.joints.border_title != "joints", what="its joints' title")
        assert app.joints.border_title == "joints of \\[b]bot"  # (the title as markup: the bracket escaped)
        assert row(app, "robots", "[b]bot")[0].plain == "[b]bot"

    drive(net.bus("top"), scenario)


def test_control_characters_from_the_bus_are_shown_not_sent_to_the_terminal(net):
    """An event's text is any JSON string: an escape sequence in it cleared the operator's
    screen and set the terminal's title, a newline broke the event list's lines."""
    script = net.bus("script")
    text = "A\x1b[2J\x1b]0;title\x07B\nC\rD\x9bE"
    bad_robot = "r\x1bbot"

    async def scenario(app, pilot):
        def put() -> None:
            script.put(keys.event("pepper", "speech"), {"t": time.time(), "kind": "speech", "text": text,
                                                        "state": "started"})
            script.put(keys.frame(bad_robot), framing.frame(time.time(), 1, ["HeadYaw"], [0.5]))

        await until(pilot, lambda: ("started" in shown(app, "event-lines") and row(app, "robots", bad_robot))
                    or put(), what="the event and the robot shown")
        await pilot.pause(0.3)  # (a redraw with both)
        lines = [line for line in shown(app, "event-lines").splitlines() if "speech" in line]
        assert len(lines) == 1 and "[2J" in lines[0] and "D" in lines[0], lines
        shown_text = shown(app, "event-lines") + shown(app, "joints") + "".join(
            c.plain for c in row(app, "robots", bad_robot)) + str(app.joints.border_title)
        assert not any((ord(c) < 0x20 and c != "\n") or 0x7f <= ord(c) <= 0x9f for c in shown_text), repr(shown_text)

    drive(net.bus("top"), scenario)


def test_a_robots_row_shows_its_shows_state_and_next_opening(net):
    """Issue 37, item 7: a closed show (a Monday) on pepper's row, "show closed, opens Tue 10:00"."""
    net.sim("pepper", rate_hz=50, idle=False)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["tue-sun 10:00-18:00"]), name="show")
    show.rehearse(1.0, start("2025-06-02 12:00", show.config.zone))

    async def scenario(app, pilot):
        await until(pilot, lambda: row(app, "robots", "pepper"), what="pepper's row")
        net.start(show)  # (its state said at start and again once it has taken the robot)
        await until(pilot, lambda: (r := row(app, "robots", "pepper")) and
                    r[-1].plain == "connected; show closed, opens Tue 10:00", what="the show's state in pepper's row")

    drive(net.bus("top"), scenario)
