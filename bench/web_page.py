"""The operator page in headless Chromium: how often it redraws the live joints, and
how long a click on a behavior takes to come back (issue 17).

A simulated Pepper (100 frames/s, idle motion) and a ``web`` node (update_hz 25) run
in one ``sonibus run`` process; Debian's Chromium, driven by Selenium, opens the
operator page. Measured in the page itself (``performance.now()``, read with
execute_script, so WebDriver's own delays are not counted):

- update rate: frames received and frames rendered (a requestAnimationFrame that
  drew new values) per second, over ``--seconds``;
- click → reply: from the behavior button's click handler to the owner's reply
  shown in the status line;
- click → running: from the click handler until the robot's ``behavior`` event
  ``started`` came back through the web node and the button shows "running"
  (click → robot event → page).

Trials alternate two short behaviors (a new one interrupts the last: no waiting for
one to end). Baseline, same run: the bus alone, this process sending
``behavior/run`` with ``client.ask`` and timing the ``started`` event's arrival.

    .venv/bin/python bench/web_page.py [--trials 100] [--seconds 10]

Writes bench/results/web_page.json and prints a table.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from common import free_port, latency_stats, write
from sink_throughput import SONIBUS, stop_process

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from tests.web.browser import Browser  # noqa: E402  (the tests' Chromium, options and all)

BEHAVIORS = ("animations/Stand/Gestures/Yes_1", "animations/Stand/Gestures/No_3")
UPDATE_HZ = 25
GOAL_HZ = 20  # issue 17: at least 20 updates/s

INSTALLATION = """\
[bus]
multicast = false

[nodes.robot]
adapter = "sim"
robot = "pepper"
rate_hz = 100
idle = true

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{port}"
update_hz = {update_hz}
"""


def update_rate(browser: Browser, seconds: float) -> dict[str, float]:
    read = "const c = sonibus.counters; return [performance.now(), c.frames, c.rendered, c.render_ms]"
    t0, frames0, rendered0, ms0 = browser.js(read)
    time.sleep(seconds)  # (a measurement window, not a wait for a condition)
    t1, frames1, rendered1, ms1 = browser.js(read)
    elapsed = (t1 - t0) / 1000
    return {"seconds": elapsed, "received_per_s": (frames1 - frames0) / elapsed,
            "rendered_per_s": (rendered1 - rendered0) / elapsed,
            "render_ms_each": (ms1 - ms0) / max(rendered1 - rendered0, 1)}


def page_round_trips(browser: Browser, trials: int) -> dict[str, list[float]]:
    """Click → reply and click → running, in seconds, ``trials`` of each."""
    browser.js("sonibus.trace.length = 0")
    for i in range(trials):
        name = BEHAVIORS[i % 2]
        button = browser.find(f'[data-robot="pepper"] [data-behavior="{name}"]')
        button.click()
        shown = (f'return document.querySelector(\'[data-behavior="{name}"]\').dataset.state === "running" '
                 f'&& sonibus.trace.filter((t) => t.what === "behavior reply").length > {i}')
        browser.wait(lambda shown=shown: browser.js(shown), f"trial {i}: {name} running")
    trace = browser.js("return sonibus.trace")
    return {what: [t["ms"] / 1000 for t in trace if t["what"] == what]
            for what in ("behavior reply", "behavior running")}


def bus_round_trips(endpoint: str, trials: int) -> list[float]:
    """``behavior/run`` sent with ``client.ask`` until its ``started`` event is here, in seconds."""
    from sonibus.bus import Bus, BusConfig, codec, open_session
    from sonibus.bus.client import ask

    session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    try:
        bus = Bus(session, node="bench-web-baseline")
        _, events = bus.subscribe("pepper/events/behavior", maxlen=10_000)
        replies: list[object] = []

        def one(i: int, timeout: float) -> float | None:
            name = BEHAVIORS[i % 2]
            answered = threading.Event()
            started = time.perf_counter()
            ask(bus, "pepper", "behavior/run", {"name": name}, lambda reply: (replies.append(reply), answered.set()))
            deadline = started + timeout
            while (item := events.get(timeout=max(deadline - time.perf_counter(), 0))) is not None:
                event = codec.decode(item[1])
                if event.get("name") == name and event.get("state") == "started":
                    elapsed = time.perf_counter() - started
                    answered.wait(5)
                    return elapsed
            return None

        # Warm up until 3 come back: a new session's subscription takes a moment to reach the robot.
        back, warm = 0, 0
        while back < 3:
            if warm == 20:
                raise RuntimeError("the robot's behavior events do not reach the benchmark's session")
            back += one(warm, 1.0) is not None
            warm += 1
        times = []
        for i in range(trials):  # (the alternation goes on from the warm-up's: the robot refuses to run again
            times.append(one(warm + i, 5.0))  # the behavior that is running, "already running")
            if times[-1] is None:
                raise RuntimeError(f"trial {i}: the behavior's started event did not come within 5 s (its reply: "
                                   f"{replies[-1] if replies else 'none'})")
        return times
    finally:
        session.close()


def _ms(stats: dict[str, float]) -> str:
    return f"{stats['p50_us'] / 1000:.1f} / {stats['p99_us'] / 1000:.1f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=10.0, help="how long the update rate is counted")
    args = parser.parse_args()

    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    endpoint, port = f"tcp/127.0.0.1:{free_port()}", free_port()
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "web.toml"
        config.write_text(INSTALLATION.format(port=port, update_hz=UPDATE_HZ))
        show = subprocess.Popen([SONIBUS, "run", str(config), "--no-multicast", "--listen", endpoint],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
        browser = None
        try:
            browser = Browser(Path(folder) / "chromium")
            deadline = time.monotonic() + 30
            while True:  # the node is up when its page loads
                if show.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the web node did not come up: {show.stderr.read()[-1000:]}")
                try:
                    browser.open(f"http://127.0.0.1:{port}/")
                    if browser.all("#stop"):
                        break
                except Exception:  # (connection refused: not listening yet)
                    pass
                time.sleep(0.2)
            browser.wait(lambda: browser.all(f'[data-behavior="{BEHAVIORS[0]}"]'), "pepper's controls", 30)
            page_round_trips(browser, 3)  # warm up
            rate = update_rate(browser, args.seconds)
            page = page_round_trips(browser, args.trials)
            base = bus_round_trips(endpoint, args.trials)
        finally:
            if browser is not None:
                browser.quit()
            stop_process(show)

    reply, running, bus = (latency_stats(page["behavior reply"]), latency_stats(page["behavior running"]),
                           latency_stats(base))
    result = {"trials": args.trials, "machine": machine, "update_hz": UPDATE_HZ, "sim_rate_hz": 100,
              "update_rate": rate, "click_to_reply": reply, "click_to_running": running,
              "baseline_bus_command_to_event": bus}
    result["summary"] = [  # the rows of bench/run.py's table
        {"scenario": f"(web) operator page updates/s (update_hz {UPDATE_HZ}, sim 100 frames/s)",
         "sonibus": f"{rate['rendered_per_s']:.1f}/s rendered ({rate['received_per_s']:.1f}/s received, "
                    f"{rate['render_ms_each']:.1f} ms each)",
         "goal": f"≥ {GOAL_HZ}/s", "met": "yes" if rate["rendered_per_s"] >= GOAL_HZ else "no"},
        {"scenario": "(web) click → robot's behavior event → page shows running, p50 / p99",
         "sonibus": _ms(running), "baseline": f"{_ms(bus)} (bus alone: ask → started event)",
         "ratio": f"{running['p50_us'] / bus['p50_us']:.1f}× / {running['p99_us'] / bus['p99_us']:.1f}×"},
        {"scenario": "(web) click → owner's reply shown, p50 / p99", "sonibus": _ms(reply)}]
    print(f"update rate over {rate['seconds']:.1f} s: {rate['rendered_per_s']:.1f} renders/s, "
          f"{rate['received_per_s']:.1f} frames/s received (update_hz {UPDATE_HZ}); "
          f"{rate['render_ms_each']:.2f} ms of script per render")
    print(f"{'ms, ' + str(args.trials) + ' trials':<44} {'p50':>7} {'p99':>7} {'max':>7}")
    for label, r in (("bus alone: ask → started event (base)", bus), ("page: click → reply shown", reply),
                     ("page: click → event → running shown", running)):
        print(f"{label:<44} {r['p50_us'] / 1000:>7.1f} {r['p99_us'] / 1000:>7.1f} {r['max_us'] / 1000:>7.1f}")
    write("web_page", result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
