"""The operator and kiosk pages in a real browser (Debian's headless Chromium through
Selenium) against a real ``web`` node and a simulated robot on a private bus: what
the page shows is checked in the page, what it makes the robot do on the bus."""

from __future__ import annotations

import urllib.error
import urllib.request

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys

from sonibus.bus import keys, send_command
from sonibus.bus.errors import CommandError, RobotNotFound

from ..conftest import Network, wait_for
from .browser import Browser
from .conftest import (
    BUTTONS,
    HELLO,
    KIOSK_TOKEN,
    NOTICE_SHOWN,
    RATE,
    TOKEN,
    WAVE,
    Stage,
    Watch,
    open_operator,
    start_web,
)
from .test_server import non_loopback_address

NOD = "animations/Stand/Gestures/Yes_1"            # a short behavior: about 1.7 s
LONG = "animations/Stand/Gestures/Enthusiastic_4"  # about 2.9 s: time to stop it

# Every change of data-state of the elements matching a selector, in the page, in order.
RECORD_STATES = """
window.seenStates = [];
for (const node of document.querySelectorAll(arguments[0])) {
  const note = () => seenStates.push([node.dataset.behavior || node.dataset.button, node.dataset.state]);
  new MutationObserver(note).observe(node, {attributes: true, attributeFilter: ["data-state"]});
}
"""

# The joints/set messages the page sends, gathered in window.sentMoves (its WebSocket's send, wrapped).
SPY_MOVES = """
const socket = sonibus.link.ws, send = socket.send.bind(socket);
window.sentMoves = [];
socket.send = (text) => {
  const message = JSON.parse(text);
  if (message.verb === "joints/set") sentMoves.push(message);
  send(text);
};
"""


@pytest.fixture
def still_stage(net: Network) -> Stage:
    """The stage of tests/web/conftest.py with a robot that moves only when told (no idle
    motion), so that a halt shows as frames that no longer change."""
    sim = net.sim("pepper", rate_hz=RATE, idle=False)
    node = start_web(net, token=TOKEN, kiosk_token=KIOSK_TOKEN, kiosk={"robot": "pepper", "buttons": BUTTONS})
    wait_for(lambda: "pepper" in node.shown_robots(), 10, "pepper's info at the web node")
    return Stage(net, sim, node)

def states_of(browser: Browser, name: str) -> list[str]:
    return [state for who, state in browser.js("return window.seenStates") if who == name]


def http_status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code


# -- operator ---------------------------------------------------------------------------


def test_the_operator_page_plots_live_joints_and_lists_the_nodes(stage, browser, figure):
    open_operator(browser, stage)
    cell = '[data-robot="pepper"] [data-joint="HeadYaw"]'
    first = browser.text(cell)
    browser.wait(lambda: browser.text(cell) != first, "HeadYaw's value to change (idle motion)")
    assert -2.09 <= float(browser.text(cell)) <= 2.09  # HeadYaw's limits, radians

    # The head's chart has traces: pixels drawn in its canvas.
    drawn = """const c = document.querySelector('[data-robot="pepper"] canvas[data-chart="Head"]');
               const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
               let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i]) n++; return n;"""
    browser.wait(lambda: browser.js(drawn) > 100, "HeadYaw and HeadPitch plotted")

    # The page draws what the server pushes, once per animation frame.
    started = browser.js("return [performance.now(), sonibus.counters.rendered, sonibus.counters.frames]")
    browser.wait(lambda: browser.js("return sonibus.counters.rendered") >= started[1] + 25, "25 more renders")
    now = browser.js("return [performance.now(), sonibus.counters.rendered, sonibus.counters.frames]")
    seconds = (now[0] - started[0]) / 1000
    figure("operator page renders", (now[1] - started[1]) / seconds, "frames/s")
    figure("operator page receives", (now[2] - started[2]) / seconds, "frames/s")

    # The nodes with their stats (the simulator and the web node itself), none gone.
    browser.wait(lambda: {"sim-pepper", "web"} <= {node.split("/")[-1]
                                                   for node in browser.attributes("#nodes tr[data-node]", "data-node")},
                 "the sim and web nodes listed")
    assert not browser.all("#nodes tr.gone")
    # Controls from pepper's info: its behaviors, the head and arm sliders within the joints' limits.
    info = stage.node.shown_robots()["pepper"]
    shown = {b.get_attribute("data-behavior") for b in browser.all('[data-robot="pepper"] [data-behavior]')}
    assert shown == set(info["behaviors"])
    limits = {j["name"]: (j["min"], j["max"]) for j in info["joints"]}
    sliders = browser.all('[data-robot="pepper"] [data-slider]')
    assert {"HeadYaw", "HeadPitch", "LShoulderPitch", "RElbowRoll"} <= {s.get_attribute("data-slider") for s in sliders}
    for slider in sliders:
        low, high = limits[slider.get_attribute("data-slider")]
        assert (float(slider.get_attribute("min")), float(slider.get_attribute("max"))) == pytest.approx((low, high))
    # STOP: large, and on screen wherever the page is scrolled.
    for scroll in ("0", "document.body.scrollHeight"):
        box = browser.js(f"window.scrollTo(0, {scroll}); const r = document.getElementById('stop')"
                         ".getBoundingClientRect(); return [r.top, r.bottom, r.width, innerHeight]")
        assert box[0] >= 0 and box[1] <= box[3] and box[2] >= 100, box
    assert browser.errors() == []


def test_a_behavior_click_runs_on_the_robot_and_shows_running_then_done(stage, browser, tmp_path):
    watch = Watch(stage.net.bus("watch"))
    open_operator(browser, stage)
    # (for the picture: two seconds of charts, and both nodes' stats)
    browser.wait(lambda: browser.js("return sonibus.counters.frames") >= 50
                 and len(browser.all("#nodes tr[data-node]")) >= 2, "charts and nodes filled")
    button = f'[data-robot="pepper"] [data-behavior="{NOD}"]'
    browser.js(RECORD_STATES, button)
    browser.find(button).click()

    watch.wait_event("behavior", "the robot to start the behavior", name=NOD, state="started")
    browser.wait(lambda: "running" in states_of(browser, NOD), "the button to show running")
    browser.wait(lambda: browser.text("#status") == "✓ pepper behavior/run", "the reply (after the event, maybe)")
    shot = browser.screenshot("web-operator.png", tmp_path)  # (the docs' pictures: test_show_size.py)
    watch.wait_event("behavior", "the robot to end the behavior", name=NOD, state="stopped")
    browser.wait(lambda: browser.attribute(button, "data-state") == "done", "the button to show done")
    states = states_of(browser, NOD)
    assert states.index("running") < states.index("done"), states
    assert "done" in browser.find(button).text
    # The event log, newest first, has the robot's events.
    log = [item.text for item in browser.all("#events li")]
    assert any(f"name={NOD} state=started" in line for line in log), log
    assert shot.width >= 600 and shot.height >= 400 and not shot.blank, shot
    assert browser.errors() == []


def test_a_slider_moves_the_joint_and_the_last_position_wins(still_stage, browser):
    watch = Watch(still_stage.net.bus("watch"))
    open_operator(browser, still_stage)
    slider = browser.find('[data-robot="pepper"] [data-slider="HeadYaw"]')
    low, high = float(slider.get_attribute("min")), float(slider.get_attribute("max"))
    width = slider.size["width"]
    # A drag from the thumb to near the right end: many input events, throttled by the page.
    drag = ActionChains(browser.driver).click_and_hold(slider)
    for _ in range(12):
        drag.move_by_offset(max(width // 30, 2), 0)
    drag.release().perform()
    target = float(slider.get_attribute("value"))  # read at once: an untouched slider follows the robot
    assert 0.2 < target <= high

    sent = wait_for(lambda: [c for c in watch.commands("joints/set") if c["args"]["angles"] == [target]], 10,
                    "the slider's last position sent", lambda: f"sent: {watch.commands('joints/set')}")
    assert sent[0]["ok"] is True and sent[0]["args"]["names"] == ["HeadYaw"]
    assert sent[0]["args"]["speed"] == pytest.approx(0.2)  # the node's configured slider speed
    wait_for(lambda: abs(watch.value("HeadYaw") - target) < 0.01, 10, f"HeadYaw at {target:.3f}",
             lambda: f"HeadYaw {watch.value('HeadYaw')}")
    assert all(low <= f["v"][f["names"].index("HeadYaw")] <= high for f in watch.frames)


def test_the_page_throttles_a_slider_and_sends_its_last_position(still_stage, browser):
    """100 moves within one script: the page sends the first at once and the last one period
    later, nothing between (the server coalesces too; this is the page's own share)."""
    watch = Watch(still_stage.net.bus("watch"))
    open_operator(browser, still_stage)
    sent = browser.js(SPY_MOVES + """
        const slider = document.querySelector('[data-robot="pepper"] [data-slider="HeadPitch"]');
        for (let i = 1; i <= 100; i++) {
          slider.value = -0.5 + i * 0.005;
          slider.dispatchEvent(new Event("input"));
        }
        return [sentMoves.length, Number(slider.value)];""")
    assert sent[0] == 1  # the first move, at once
    last = sent[1]
    moves = browser.wait(lambda: len(browser.js("return sentMoves")) >= 2 and browser.js("return sentMoves"),
                         "the held last move")
    assert [m["args"]["angles"] for m in moves] == [[pytest.approx(-0.495, abs=0.01)], [last]]
    wait_for(lambda: [c for c in watch.commands("joints/set") if c["args"]["angles"] == [last]], 10,
             "the robot to get the last position", lambda: f"got: {watch.commands('joints/set')}")


def test_a_slider_move_held_by_the_page_is_dropped_by_stop(still_stage, browser):
    watch = Watch(still_stage.net.bus("watch"))
    open_operator(browser, still_stage)
    browser.js(SPY_MOVES + """
        const slider = document.querySelector('[data-robot="pepper"] [data-slider="HeadPitch"]');
        for (const value of [0.1, 0.3]) {  // the first goes at once, the second is held for a period
          slider.value = value;
          slider.dispatchEvent(new Event("input"));
        }
        sonibus.stop();
        // A timer due after the held move's: timers run in the order they are due.
        setTimeout(() => { window.movesAfterStop = sentMoves.length; }, 2000 / sonibus.settings.slider_hz);""")
    assert browser.wait(lambda: browser.js("return window.movesAfterStop"), "two periods after the stop") == 1
    watch.wait_event("command", "the robot's stop", verb="stop")
    watch.wait_event("command", "the first move", verb="joints/set")
    assert [c["args"]["angles"] for c in watch.commands("joints/set")] == [[pytest.approx(0.1, abs=0.01)]]
    browser.wait(lambda: browser.text("#status") == "STOP: ✓ pepper", "the stop's reply shown")


def test_an_out_of_range_request_shows_the_owners_error(still_stage, browser):
    bus = still_stage.net.bus("asker")
    open_operator(browser, still_stage)
    # A slider forced past its max, as a page with its limits tampered with would send.
    browser.js("""const s = document.querySelector('[data-robot="pepper"] [data-slider="HeadYaw"]');
                  s.step = "any"; s.max = 10; s.value = 5; s.dispatchEvent(new Event("input"));""")

    def owner_says() -> str | None:
        """The owner's refusal of the same request, asked on the bus."""
        try:
            send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [5.0], "speed": 0.2})
        except RobotNotFound:
            return None  # (a new session: routes to the robot's queryable not known yet)
        except CommandError as exc:
            return exc.message
        pytest.fail("the robot took HeadYaw = 5.0 rad")
    refusal = wait_for(owner_says, 10, "the owner's answer on the bus")
    assert "HeadYaw" in refusal and "limits" in refusal
    browser.wait(lambda: refusal in (browser.text("#status") or ""), "the owner's error shown")
    assert browser.attribute("#status", "data-kind") == "error"


def test_space_and_escape_stop_the_robot_but_space_types_in_the_say_box(still_stage, browser):
    watch = Watch(still_stage.net.bus("watch"))
    open_operator(browser, still_stage)
    button = browser.find(f'[data-robot="pepper"] [data-behavior="{LONG}"]')
    button.click()
    watch.wait_event("behavior", "the behavior started", name=LONG, state="started")
    wait_for(lambda: not watch.still(3), 10, "the robot moving")

    # Space on the page (the behavior button still has the focus: it must not run again).
    ActionChains(browser.driver).send_keys(Keys.SPACE).perform()
    watch.wait_event("command", "the robot to get stop", verb="stop")
    watch.wait_event("behavior", "the behavior to stop", name=LONG, state="stopped")
    wait_for(lambda: watch.still(RATE // 2), 10, "the robot halted (half a second of identical frames)")
    assert len(watch.event("behavior", name=LONG, state="started")) == 1  # Space did not press the button
    browser.wait(lambda: browser.text("#status") == "STOP: ✓ pepper", "the stop's reply shown")
    # Issue 37, item 6: the robot's line said "connected idle" after STOP; it says it is held
    # until the robot carries out its next command (a listing is none)
    line = '[data-summary="pepper"] .summary-doing'
    browser.wait(lambda: browser.text(line) == "stopped — held still", "the robot's line: held still")
    assert "next command" in browser.attribute(line, "title")
    send_command(still_stage.net.bus("asker"), "pepper", "behavior/list")
    send_command(still_stage.net.bus("mover"), "pepper", "posture", {"name": "Stand"})
    browser.wait(lambda: browser.text(line) != "stopped — held still", "the hold ended by the posture")

    # In the say box Space is a space; Escape stops from anywhere.
    say = browser.find('[data-say="pepper"]')
    say.click()
    say.send_keys("hello there")
    assert say.get_attribute("value") == "hello there"
    say.send_keys(Keys.ESCAPE)
    wait_for(lambda: len(watch.commands("stop")) >= 2, 10, "Escape's stop")
    assert len(watch.commands("stop")) == 2  # (the robot answers in order: a stop from the typed space came first)
    assert browser.errors() == []


def test_say_posture_and_awareness_reach_the_robot(still_stage, browser):
    watch = Watch(still_stage.net.bus("watch"))
    open_operator(browser, still_stage)
    say = browser.find('[data-say="pepper"]')
    say.send_keys("hello visitors", Keys.ENTER)
    watch.wait_event("speech", "the robot to say it", text="hello visitors", state="started")
    assert say.get_attribute("value") == ""  # sent, so cleared
    browser.find('[data-robot="pepper"] [data-posture="Crouch"]').click()
    watch.wait_event("posture", "the posture to start", name="Crouch", state="started")
    browser.find('[data-awareness="pepper"]').click()
    notice = watch.wait_event("command", "awareness on", verb="awareness")
    assert notice["args"] == {"enabled": True} and notice["ok"] is True
    browser.wait(lambda: browser.text("#status") == "✓ pepper awareness", "its reply shown")


def test_a_node_turns_amber_when_a_loss_counter_moves_and_red_when_gone(still_stage, browser):
    nao = still_stage.net.sim("nao", rate_hz=10)
    open_operator(browser, still_stage)
    row = "#nodes tr[data-node$='/{}']".format
    browser.wait(lambda: browser.attribute(row("web"), "data-state") == "ok"
                 and browser.attribute(row("sim-nao"), "data-state") == "ok", "the web and nao nodes listed, fine")
    # Bytes that are no frame, on a key the web node takes: its gate refuses them, counted 'bad'.
    vandal = still_stage.net.bus("vandal").session

    def amber() -> bool:
        vandal.put(keys.frame("pepper"), b"\xc1 no msgpack")  # (again: the first may leave before routes are known)
        return browser.attribute(row("web"), "data-state") == "warning"
    browser.wait(amber, "the web node amber")
    assert "bad " in browser.text(row("web"))
    assert browser.all('[data-robot="nao"] [data-slider="LElbowRoll"]')  # (a NAO shown too: arms, legs)
    nao.stop()
    browser.wait(lambda: browser.attribute(row("sim-nao"), "data-state") == "gone", "nao's node red (gone)")
    assert "gone" in browser.attribute(row("sim-nao"), "class")
    assert browser.attribute(row("sim-pepper"), "data-state") == "ok"
    assert browser.errors() == []


def test_the_page_shows_disconnected_and_reconnects(still_stage, browser):
    open_operator(browser, still_stage)
    port = still_stage.node.web.port
    still_stage.node.stop()
    browser.wait(lambda: browser.attribute("#connection", "data-state") == "disconnected", "disconnected shown")
    assert "disconnected" in browser.text("#connection")
    assert browser.js("return document.body.classList.contains('disconnected')")
    start_web(still_stage.net, name="web2", listen=f"127.0.0.1:{port}", token=TOKEN)
    browser.wait(lambda: browser.attribute("#connection", "data-state") == "connected", "reconnected", timeout=20)
    frames = browser.js("return sonibus.counters.frames")
    browser.wait(lambda: browser.js("return sonibus.counters.frames") > frames + 5, "frames again")


# -- kiosk ------------------------------------------------------------------------------


def test_the_kiosk_has_only_its_buttons_and_follows_the_robot(stage, browser, tmp_path):
    watch = Watch(stage.net.bus("watch"))
    browser.open(stage.kiosk_url)
    browser.wait(lambda: len(browser.all("[data-button]")) == len(BUTTONS), "the kiosk's buttons")
    assert [b.get_attribute("data-button") for b in browser.all("[data-button]")] == [b["id"] for b in BUTTONS]
    assert [b.find_element("css selector", ".label").text for b in browser.all("[data-button]")] == \
        [b["label"] for b in BUTTONS]
    # Nothing else to reach: no stop, sliders, behaviors, postures, text boxes; every button is a kiosk button.
    for operator_control in ("#stop", "[data-slider]", "[data-behavior]", "[data-posture]", "[data-say]",
                             "[data-awareness]", "input", "textarea", "select", "a[href]"):
        assert not browser.all(operator_control), operator_control
    assert len(browser.all("button")) == len(BUTTONS)

    browser.js(RECORD_STATES, "[data-button]")
    browser.find('[data-button="wave"]').click()
    watch.wait_event("behavior", "the robot to run the wave", name=WAVE, state="started")
    browser.wait(lambda: browser.attribute('[data-button="wave"]', "data-state") == "running", "wave running")
    assert not browser.find('[data-button="hello"]').is_enabled()  # one scenario at a time
    shot = browser.screenshot("web-kiosk.png", tmp_path)
    watch.wait_event("behavior", "the wave to end", name=WAVE, state="stopped")
    browser.wait(lambda: browser.attribute('[data-button="wave"]', "data-state") == "done", "wave done")
    assert states_of(browser, "wave") == ["running", "done"]
    assert browser.find('[data-button="hello"]').is_enabled()

    browser.find('[data-button="hello"]').click()
    watch.wait_event("speech", "the robot to say it", text=HELLO, state="done")
    browser.wait(lambda: browser.attribute('[data-button="hello"]', "data-state") == "done", "hello done")
    assert states_of(browser, "hello") == ["running", "done"]
    assert not shot.blank, shot
    assert browser.errors() == []


def test_the_kiosk_disables_its_buttons_while_disconnected(still_stage, browser):
    browser.open(still_stage.kiosk_url)
    browser.wait(lambda: browser.js("return sonibus.link.connected"), "the kiosk connected")
    assert browser.find('[data-button="wave"]').is_enabled()
    port = still_stage.node.web.port
    still_stage.node.stop()
    browser.wait(lambda: browser.js(NOTICE_SHOWN), "the kiosk's notice")
    assert not any(button.is_enabled() for button in browser.all("[data-button]"))
    start_web(still_stage.net, name="web2", listen=f"127.0.0.1:{port}", token=TOKEN, kiosk_token=KIOSK_TOKEN,
              kiosk={"robot": "pepper", "buttons": BUTTONS})
    browser.wait(lambda: browser.js("return sonibus.link.connected"), "reconnected", timeout=20)
    assert not browser.js(NOTICE_SHOWN)
    browser.wait(lambda: all(button.is_enabled() for button in browser.all("[data-button]")), "buttons usable again")
    assert len(browser.all("[data-button]")) == len(BUTTONS)


def test_operator_urls_refuse_the_kiosk_token(stage, browser):
    base = stage.url
    for path in ("/", "/ws"):
        assert http_status(f"{base}{path}?token={KIOSK_TOKEN}") == 403, path
        assert http_status(f"{base}{path}") == 403, path
    assert http_status(f"{base}/kiosk?token={KIOSK_TOKEN}") == 200
    browser.open(f"{base}/?token={KIOSK_TOKEN}")
    assert browser.find("body").text.startswith("403")
    assert not browser.all("#stop")


def test_from_another_address_the_pages_work_with_their_token_only(net, browser, tmp_path):
    """Served on every address, opened at this machine's LAN address (the server sees a peer
    that is not loopback): no token → 403; with it the page's WebSocket gets it too."""
    net.sim("pepper", rate_hz=RATE)
    image = tmp_path / "wave.png"
    image.write_bytes(browser.driver.get_screenshot_as_png())  # any PNG will do
    buttons = [{**BUTTONS[0], "image": str(image)}, BUTTONS[1]]
    node = start_web(net, listen="0.0.0.0:0", token=TOKEN, kiosk_token=KIOSK_TOKEN,
                     kiosk={"robot": "pepper", "buttons": buttons})
    base = f"http://{non_loopback_address()}:{node.web.port}"
    browser.open(f"{base}/")
    assert browser.find("body").text.startswith("403")
    browser.open(f"{base}/?token={TOKEN}")
    browser.wait(lambda: browser.attribute("#connection", "data-state") == "connected", "connected over the LAN")
    browser.wait(lambda: browser.all('[data-robot="pepper"] [data-joint="HeadYaw"]'), "pepper shown")
    browser.open(f"{base}/kiosk?token={KIOSK_TOKEN}")
    browser.wait(lambda: browser.js("return sonibus.link.connected"), "the kiosk connected")
    loaded = "const i = document.querySelector('[data-button=\"wave\"] img'); return i && i.complete && i.naturalWidth"
    assert browser.wait(lambda: browser.js(loaded), "the wave button's image") > 0
    assert browser.errors() == []


def test_screenshots_are_checked_for_blankness(browser, tmp_path):
    """The blank check itself: an empty page is blank, a drawn one is not."""
    browser.open("about:blank")
    assert browser.screenshot("blank.png", tmp_path).blank
    browser.js("""document.body.innerHTML = '<h1>sonibus</h1>' + 'text '.repeat(400);
                  document.body.style.cssText = 'background: #123; color: #fe9; font-size: 20px';""")
    assert not browser.screenshot("drawn.png", tmp_path).blank



def test_frames_per_second_are_the_robots_not_the_pages(net, browser):
    """Issue 37, item 4: the page showed its own push rate (25 frames/s, ``update_hz``) for a robot
    at 100, while ``sonibus top`` showed 100. The figure is the robot's, from its frames' ``seq``
    and ``t``; the page's own rate is in the label's title, said as such; a robot gone silent reads 0."""
    sim = net.sim("pepper", rate_hz=100, idle=True)
    node = start_web(net, token=TOKEN)
    wait_for(lambda: "pepper" in node.shown_robots(), 10, "pepper's info at the web node")
    open_operator(browser, Stage(net, sim, node))
    label = '[data-robot="pepper"] .robot-rate'

    def shown() -> float:
        text = browser.text(label)
        return float(text.split()[0]) if text.endswith("frames/s") else -1.0

    browser.wait(lambda: shown() > 0, "a rate shown")
    browser.wait(lambda: shown() > 0 and browser.text(label) == browser.text(".summary-rate"), "both rates shown")
    assert 90 <= shown() <= 110, f"{browser.text(label)} shown for a robot at 100 frames/s"
    assert "this page draws" in browser.attribute(label, "title")
    sim.stop()  # the robot falls silent: its rate is 0, not its last figure
    browser.wait(lambda: shown() == 0, "0 frames/s once the robot is silent")
