"""The console view on a real bus: a robot's frames, or with ``per_joint_keys`` its
joint keys (and not its frames), in the line it prints."""

from __future__ import annotations

import io
import time

import pytest

from sonibus.adapters.console import ConsoleConfig, ConsoleView
from sonibus.bus import framing, keys

from .conftest import wait_for


@pytest.mark.parametrize("per_joint_keys", [False, True], ids=["frames", "joint-keys"])
def test_the_view_shows_frames_or_with_per_joint_keys_the_joint_keys(net, per_joint_keys):
    view = ConsoleView(ConsoleConfig(every_s=0.1, per_joint_keys=per_joint_keys), name="view")
    view.out = io.StringIO()
    net.start(view)
    script = net.bus("script")
    seq = 0

    heard, unheard = ("HeadPitch +0.250", "HeadYaw") if per_joint_keys else ("HeadYaw +0.500", "HeadPitch")

    def shown() -> list[str]:
        """Put a joint key alone, then a frame of another joint; the lines that show what is heard."""
        nonlocal seq
        seq += 1
        script.put(keys.joint("bot", "HeadPitch"), {"t": time.time(), "seq": seq, "v": 0.25})
        script.put(keys.frame("bot"), framing.frame(time.time(), seq, ["HeadYaw"], [0.5]))
        return [line for line in view.out.getvalue().splitlines() if heard in line]

    lines = wait_for(shown, what=f"a line with {heard}")
    assert lines[0].startswith("bot ")
    assert unheard not in view.out.getvalue()


def test_a_robot_that_leaves_the_bus_leaves_the_view(net):
    """Issue 19, item 6: a replay that ended stayed in the view at 0.0 frames/s for ever."""
    view = ConsoleView(ConsoleConfig(every_s=0.1), name="view")
    view.out = io.StringIO()
    net.start(view)
    net.sim("pepper", rate_hz=20)  # stays: its lines show the view going on
    robot = net.sim("nao", rate_hz=50)
    wait_for(lambda: "\nnao " in view.out.getvalue(), what="a line for nao")
    robot.stop()
    wait_for(lambda: "nao      left the bus" in view.out.getvalue(), timeout=15, what="nao leaving the view")
    wait_for(lambda: view.out.getvalue().partition("nao      left the bus")[2].count("pepper ") >= 3,
             what="three more lines of the view")
    after = view.out.getvalue().partition("nao      left the bus")[2]
    assert "nao " not in after, after
