"""The shipped examples with ``multicast = false`` listen on a fixed endpoint that ``sonibus
run`` prints, and the one-shot commands join them with ``--config FILE`` alone. Each runs
unchanged (its fixed ports too) in a machine of its own: a network namespace."""

from __future__ import annotations

import re
from pathlib import Path

from ..conftest import wait_for

EXAMPLES = Path(__file__).resolve().parent.parent.parent / "examples"
NO_MULTICAST = sorted(p.name for p in EXAMPLES.glob("*.toml") if re.search(r"^multicast = false", p.read_text(), re.M))


def test_every_example_without_multicast_is_here():
    assert NO_MULTICAST == ["kiosk.toml", "oscquery.toml", "ros2-arm.toml", "web.toml"]


def test_the_examples_without_multicast_are_joined_with_their_file(topology):
    hosts = topology.lan(*(name.removesuffix(".toml").replace("-", "") for name in NO_MULTICAST))
    examples = [str(EXAMPLES / name) for name in NO_MULTICAST]
    runs = [host.sonibus("run", example) for host, example in zip(hosts, examples, strict=True)]  # all at once
    for name, host, example, run in zip(NO_MULTICAST, hosts, examples, runs, strict=True):
        fixed = re.search(r'^listen = \["([^"]+:[1-9]\d*)"\]', (EXAMPLES / name).read_text(), re.M)
        assert fixed, f"examples/{name} has no fixed listen endpoint in its [bus]: nothing could join it by its file"
        endpoint = fixed[1]
        bus = wait_for(lambda run=run: [line for line in run.lines if line.startswith("sonibus: bus: ")], 30,
                       f"{name}'s bus line", run.describe)[0]
        assert f"listening on {endpoint} — join from this machine with --config {example}, or --connect " \
               f"{endpoint} " in bus, bus

        # (a ROS 2 robot answers stop only once its controller is matched: until then it says it reached none)
        def matched(host=host, example=example):
            found = host.cli("nodes", "--config", example)
            return found.returncode == 0 and "NOT MATCHED" not in found.stdout and found

        nodes = wait_for(matched, 20, f"{name}'s robot and its controller")
        robot = re.search(r"^\s*robot (\S+) .* owned by ", nodes.stdout, re.M)
        assert nodes.returncode == 0 and robot, f"{name}: {nodes.stdout}{nodes.stderr}"
        sent = host.cli("send", robot[1], "stop", "--config", example)
        assert sent.returncode == 0, f"{name}: {sent.stderr}"
    for run in runs:
        code, _, err = run.stop()
        assert code == 130, err
