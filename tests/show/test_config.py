"""The show's options: every mistake is one line naming the file, the table, the key
and what it should be; nothing starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from sonibus.bus import config, runner
from sonibus.bus.errors import ConfigError

from ..conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]
SHOW = '''
[nodes.show]
adapter = "show"
robot = "pepper"
timezone = "Europe/Paris"
hours = ["tue-sun 10:00-18:00"]

[nodes.show.idle]
behaviors = ["animations/Stand/Gestures/Hey_1"]

[nodes.show.scenarios.hello]
steps = [{say = "Hello!"}, {behavior = "animations/Stand/Gestures/Hey_1"}, {pause_s = 2}, {posture = "Stand"}]
'''


def build(text: str) -> list:
    return runner.build(config.parse(text, "show.toml"))


def test_a_show_builds_with_its_hours_idle_and_scenarios():
    show = build(SHOW)[0]
    assert show.config.schedule.describe() == "tue,wed,thu,fri,sat,sun 10:00-18:00 (Europe/Paris)"
    assert [s.kind for s in show.config.program["hello"].steps] == ["say", "behavior", "pause", "posture"]
    assert show.config.gestures.rest_s == 120 and show.config.gestures.max_per_hour == 20


@pytest.mark.parametrize("change, message", [
    (('timezone = "Europe/Paris"', ""), r"show.toml \[nodes.show\]: key 'timezone': is missing: the hours are "
                                        r"local time of which zone\?"),
    (('"Europe/Paris"', '"Europe/Pariss"'), r"line 5: key 'timezone': 'Europe/Pariss' is not a time zone"),
    (('"tue-sun 10:00-18:00"', '"tue-sun 18:00-10:00"'), r"line 6: key 'hours': .* closes at 10:00"),
    (('{pause_s = 2}', '{pause_s = 2, say = "hi"}'), r"key 'scenarios': scenarios.hello.steps\[2\]: key 'steps': "
                                                     r"a step needs exactly one of .* got say, pause_s"),
    (('{pause_s = 2}', '{pause = 2}'), r"scenarios.hello.steps\[2\]: unknown key 'pause' — known keys: behavior, "
                                       r"say, posture, pause_s"),
    (('scenarios.hello]', 'scenarios."hello there"]'), r"'hello there': a scenario's name must be"),
    (('behaviors = ', 'rest_s = -1\nbehaviors = '), r"key 'idle': idle: key 'rest_s': -1 must be in"),
    (('behaviors = ', 'order = "shuffle"\nbehaviors = '), r"'shuffle' is not one of 'random', 'in order'"),
])
def test_a_mistake_is_one_line_naming_where_and_the_fix(change, message):
    with pytest.raises(ConfigError, match=message):
        build(SHOW.replace(*change))


def test_museum_toml_has_no_simulator_key_and_its_one_robot_line_makes_it_a_naoqi_show():
    """The file says which line to change; that line alone turns the sim into a real robot,
    and the simulator-only keys of the old museum (idle, autoplay_s) are gone."""
    text = (ROOT / "examples" / "museum.toml").read_text(encoding="utf-8")
    said = next(line.strip().removeprefix("#").strip() for line in text.splitlines()
                if line.strip().startswith("#") and 'adapter = "naoqi"' in line)
    robot_lines = [line for line in text.splitlines() if line.startswith("robot = { adapter = ")]
    assert len(robot_lines) == 1 and said.startswith("robot = {")
    real = text.replace(robot_lines[0], said.replace("<robot ip>", "192.168.1.20"))
    assert sum(a != b for a, b in zip(text.splitlines(), real.splitlines(), strict=True)) == 1
    adapters = runner.build(config.parse(real, "museum.toml"))
    assert [a.kind for a in adapters][:2] == ["naoqi", "show"]
    assert adapters[0].config.url == "tcp://192.168.1.20:9559"
    assert "autoplay_s" not in text and "\nidle = " not in text


def test_an_inline_robot_tables_mistake_names_its_line():
    text = (ROOT / "examples" / "museum.toml").read_text(encoding="utf-8")
    wrong = text.replace('robot = { adapter = "sim", robot = "pepper" }',
                         'robot = { adapter = "naoqi", robot = "pepper", autoplay_s = 20 }')
    line = next(i for i, t in enumerate(wrong.splitlines(), 1) if "autoplay_s = 20 }" in t)
    with pytest.raises(ConfigError, match=rf"museum.toml \[nodes.robot\] line {line}: unknown key 'autoplay_s'"):
        runner.build(config.parse(wrong, "museum.toml"))


def test_the_show_pages_first_example_builds():
    text = (ROOT / "docs" / "show.md").read_text(encoding="utf-8")
    example = text.split("```toml\n", 1)[1].split("```", 1)[0]
    assert [a.kind for a in build(example)] == ["sim", "show"]


@pytest.mark.parametrize("args, message", [
    (["--day", "10"], "rehearse: '10' is not a duration like 10m, 90s or 1h"),
    (["--from", "25:00"], "rehearse: --from: '25:00' is not a time like 09:55"),
    (["--from", "2026-03-29 02:30"], "rehearse: --from: '2026-03-29 02:30' does not exist in Europe/Paris: that "
                                     "night the clocks go from 02:00 to 03:00 — give a time before or after the jump"),
    (["--only", "robot"], "no show node among robot — a rehearsal speeds up the clock of the show nodes"),
])
def test_a_rehearsal_that_cannot_run_says_why_in_one_line_and_starts_nothing(args, message):
    done = run_cli("rehearse", str(ROOT / "examples" / "museum.toml"), "--no-multicast", *args)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("sonibus: error: ") and message in lines[0]
