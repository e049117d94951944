"""``sonibus top`` in an 80×24 terminal (issue 29, item 11): it cut off the joints'
values and limits, two joints, the events' text and the nodes' last counter
(docs/top.md asked for 150×30). Checked on what the screen really shows (textual's
pilot, the app against a simulator and an OSC sink on a private bus)."""

from __future__ import annotations

import asyncio
import re

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus.cli.top import TopApp
from sonibus.bus.monitor import Monitor

from .pilot import until

BEHAVIOR = "started animations/Stand/Gestures/Hey_1"


def screen(app: TopApp) -> list[str]:
    """The terminal's lines as drawn."""
    return ["".join(segment.text for segment in strip) for strip in app.screen._compositor.render_strips()]


def test_at_80_by_24_every_joint_value_limit_event_and_counter_is_on_screen(net):
    net.sim("pepper", rate_hz=50, idle=True)
    net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=("127.0.0.1:9",)), name="sound"))
    bus = net.bus("top")
    shown: list[str] = []

    async def run() -> None:
        with Monitor(bus) as monitor:
            app = TopApp(monitor, every_s=0.1)
            async with app.run_test(size=(80, 24)) as pilot:
                await until(pilot, lambda: len(app.snapshot.nodes) == 2 and app.snapshot.robots
                            and all(j.min is not None for j in app.snapshot.robots[0].joints)
                            and app.snapshot.robots[0].joints, timeout=20, what="the robot, its limits, two nodes")
                monitor.note("pepper", "behavior", BEHAVIOR)
                await until(pilot, lambda: any(BEHAVIOR in line for line in screen(app)), what="the event drawn")
                app.redraw()
                await pilot.pause()
                robot = app.snapshot.robots[0]
                shown[:] = screen(app)
                text = "\n".join(shown)
                for joint in robot.joints:
                    found = re.search(rf"\b{joint.name} +([+-]\d\.\d{{3}})(?: frac)? +{re.escape(f'{joint.min:+.2f}')}"
                                      rf"\.\.{re.escape(f'{joint.max:+.2f}')}", text)
                    assert found, f"{joint.name}, its value and its limits are not on screen:\n{text}"

    asyncio.run(run())
    assert len(shown) == 24 and all(len(line) <= 80 for line in shown)
    for node in ("sim-pepper", "sound"):  # every counter, the last one too
        line = next(line for line in shown if f"/{node} " in line and " running " in line)
        assert re.search(r"running +[\d,]+ +[\d,]+ +[\d,]+ +[\d,]+ +[\d,]+ +[\d,]+\s*$", line), line
