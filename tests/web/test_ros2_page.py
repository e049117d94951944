"""A ROS 2 arm on the operator page (issue 37, item 1), in a real headless Chromium: the
panel is built from the robot's info — its chains and joints, sliders for each chain with
units (a prismatic joint in metres) — and offers only the verbs the robot carries out.
Before: sliders only for Pepper's and NAO's Head and arms (by joint name), so the arm's
joints landed in "Body" with no slider, while Say and Awareness (which the arm refuses)
were offered."""

from __future__ import annotations

from sonibus.adapters.ros2.sim import SimArm, SimArmConfig

from ..conftest import wait_for
from ..ros2.conftest import ARM_URDF, start_arm
from .conftest import TOKEN, start_web


def test_a_ros2_arm_gets_sliders_for_its_chains_with_units_and_only_its_verbs(net, browser):
    sim = net.start(SimArm(SimArmConfig(urdf=str(ARM_URDF), idle=False, rate_hz=50.0), name="arm-sim"))
    arm = start_arm(net)
    wait_for(lambda: not arm.link.matched(), 10, "the stand-in's controller matched")
    web = start_web(net, token=TOKEN, robots=("arm",))
    wait_for(lambda: "arm" in web.shown_robots(), 10, "the arm's info at the web node")
    browser.open(f"{web.url}/?token={TOKEN}#arm")
    browser.wait(lambda: browser.all('[data-robot="arm"] [data-slider]'), "the arm's sliders")

    sliders = set(browser.attributes('[data-robot="arm"] [data-slider]', "data-slider"))
    assert {"lift", "shoulder", "elbow", "wrist", "head_pan"} <= sliders, sliders
    groups = set(browser.attributes('[data-robot="arm"] .slider-group', "data-group"))
    assert {"tool", "camera"} <= groups, groups  # the chains the installation names (tests/ros2/conftest.py)
    # Only what the arm carries out: postures (its installation names none here) and sliders; no speech,
    # behaviors nor awareness
    assert not browser.all('[data-say="arm"]') and not browser.all('[data-awareness="arm"]')
    assert not browser.all('[data-robot="arm"] .behaviors')
    assert browser.all('[data-robot="arm"] .postures')

    # Every value with its unit: the prismatic lift in metres, the shoulder in radians
    lift = '[data-robot="arm"] [data-slider="lift"]'
    browser.wait(lambda: (browser.text(lift + " + output") or "").endswith(" m"), "the lift's value in metres")
    assert browser.text('[data-robot="arm"] [data-slider="shoulder"] + output').endswith(" rad")
    units = browser.js("""return Object.fromEntries([...document.querySelectorAll('[data-robot="arm"] .joint')]
                          .map((row) => [row.querySelector('.name').textContent,
                                         row.querySelector('.unit').textContent]))""")
    assert units["lift"] == "m" and units["shoulder"] == "rad", units

    # A slider moves the arm: joints/set through the page, to the stand-in's controller
    target = float(browser.js(f"""const s = document.querySelector('{lift}'); s.value = 0.03;
                                   s.dispatchEvent(new Event('input', {{bubbles: true}})); return s.value;"""))
    # (0.03 on the slider's steps: a thousandth of its range; the lift runs at 0.2 × 0.1 m/s)
    assert abs(target - 0.03) < 0.001
    wait_for(lambda: abs(sim.position["lift"] - target) < 1e-6, 15, f"the lift at {target} m",
             lambda: f"lift at {sim.position.get('lift')}")
    assert browser.errors() == []
