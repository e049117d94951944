"""What the README promises of the command line holds (issue 29, items 8, 9, 10, 13):
its exit-code table is the one commands use, `record` and `echo` have the flags their
siblings have, replies carry numbers made for people, and every node's counters are
in its stop line."""

from __future__ import annotations

import io
import json
import re
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.adapters.recorder.reading import Recording
from sonibus.bus import robot_info
from sonibus.bus.cli import Environment, Exit, main

from .conftest import SONIBUS, free_port, wait_for
from .osc.test_gateway import Client

ROOT = Path(__file__).resolve().parent.parent


def run(*argv: str) -> tuple[int, str, str]:
    """``sonibus ARGV`` in this process: its status, stdout and stderr."""
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    status = main(list(argv), env)
    return status, env.stdout.getvalue(), env.stderr.getvalue()


def error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if not line.startswith("sonibus: hint: ")]
    assert len(lines) == 1 and lines[0].startswith("sonibus: error: "), err
    return lines[0]


# -- item 8: exit codes --------------------------------------------------------------------


def readme_exit_codes() -> dict[int, str]:
    """The README's table of exit statuses: status → when."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text.partition("| exit status |")[2].partition("\n\n")[0]
    return {int(m[1]): m[2] for m in re.finditer(r"^\| `(\d+)` \| (.*) \|$", table, re.MULTILINE)}


def test_the_readme_lists_every_exit_status_and_only_those():
    assert readme_exit_codes().keys() == {int(e) for e in Exit}


def test_an_unknown_verb_is_a_usage_error_said_before_the_bus_is_joined():
    """Issue 29, item 8: `sonibus send pepper jump` exited 4 (refused) — or 3 with no robot."""
    status, _, err = run("send", "pepper", "jump", "--no-multicast")
    assert status == Exit.USAGE == 2
    assert error_line(err) == ("sonibus: error: unknown command 'jump' — known commands: awareness, behavior/list, "
                               "behavior/run, behavior/stop, joints/set, posture, say, stiffness, stop")
    assert "send pepper jump" in readme_exit_codes()[2]


def test_a_robot_already_owned_is_a_configuration_mistake(net, tmp_path):
    """Issue 29, item 8: "already owned" exited 1; the README files two owners of one robot under 2."""
    net.sim("pepper")
    show = tmp_path / "show.toml"
    show.write_text('[nodes.second]\nadapter = "sim"\nrobot = "pepper"\n')
    status, _, err = run("run", str(show), *net.cli_args())
    assert status == Exit.USAGE
    assert "robot 'pepper' is already owned by node 'sim-pepper'" in error_line(err)
    assert "already owned" in readme_exit_codes()[2]


def test_a_recording_that_heard_nothing_exits_3_as_the_readme_says(net, tmp_path):
    status, _, err = run("record", str(tmp_path / "empty.mcap"), "--duration", "0.5", *net.cli_args())
    assert status == Exit.NOT_FOUND == 3
    assert "recorded nothing" in err
    assert "heard nothing" in readme_exit_codes()[3]


# -- item 9: the flags a command's siblings have ---------------------------------------------


def test_record_overwrites_only_when_told_with_the_recorder_nodes_word(net, tmp_path):
    """Issue 29, item 9: `record` had `--force` where the recorder node has `overwrite`."""
    net.sim("pepper", rate_hz=50)
    path = tmp_path / "take.mcap"
    path.write_bytes(b"an earlier take")
    status, _, err = run("record", str(path), "--duration", "0.5", *net.cli_args())
    assert status == Exit.USAGE
    assert "exists — choose another name, or overwrite it (--overwrite, overwrite = true)" in error_line(err)
    assert path.read_bytes() == b"an earlier take"
    status, _, err = run("record", str(path), "--overwrite", "--duration", "1", *net.cli_args())
    assert status == Exit.OK, err
    with Recording(str(path)) as recording:
        assert recording.message_count > 0
    status, _, err = run("record", str(path), "--force", "--duration", "0.5", *net.cli_args())
    assert status == Exit.OK, err  # (the word it had before still works)


def test_echo_gives_up_after_its_timeout_with_status_5(net):
    """Issue 29, item 9: `send` and `info` had --timeout, `echo` had none: a script waited for ever."""
    status, out, err = run("echo", "pepper/frame", "--timeout", "0.5", *net.cli_args())
    assert status == Exit.TIMEOUT == 5
    assert error_line(err) == "sonibus: error: echo 'pepper/frame': no sample for 0.5 s"
    assert out == ""
    net.sim("pepper", rate_hz=50)
    status, out, err = run("echo", "pepper/frame", "--count", "3", "--timeout", "10", *net.cli_args())
    assert status == Exit.OK, err
    assert len(out.splitlines()) == 3
    status, _, err = run("echo", "pepper/frame", "--timeout", "0", *net.cli_args())
    assert status == Exit.USAGE and "--timeout 0" in error_line(err)


# -- item 10: numbers made for people --------------------------------------------------------


def _noisy(value: object) -> list[float]:
    """The floats in ``value`` that carry more than millisecond digits (3.1000000000000005)."""
    if isinstance(value, float):
        return [] if repr(value) == repr(round(value, 3)) else [value]
    if isinstance(value, dict):
        return [f for v in value.values() for f in _noisy(v)]
    if isinstance(value, list):
        return [f for v in value for f in _noisy(v)]
    return []


def test_replies_carry_no_float_noise_to_the_command_line_nor_to_pd(net):
    """Issue 29, item 10: `behavior/run` answered "duration": 3.1000000000000005, in the
    JSON text the gateway sends Pd too."""
    net.sim("pepper", rate_hz=50)
    port = free_port(socket.SOCK_DGRAM)
    gate = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{port}"), name="gate"))
    client = Client(gate.udp_address)
    watch = net.bus("watch")
    behaviors = wait_for(lambda: (robot_info(watch, "pepper", timeout=0.5) or {}).get("behaviors"), what="its info")
    try:
        for behavior in behaviors:
            status, out, err = run("send", "pepper", "behavior/run", behavior, *net.cli_args())
            assert status == Exit.OK, err
            assert not _noisy(json.loads(out)), out
            run("send", "pepper", "stop", *net.cli_args())
            address, (ok, text) = client.ask("/pepper/cmd/behavior/run", behavior)
            assert (address, ok) == ("/pepper/reply/behavior/run", 1), text
            assert not _noisy(json.loads(text)), text
            client.ask("/pepper/cmd/stop")
    finally:
        client.sock.close()


# -- item 13: a stop line per node -----------------------------------------------------------


@pytest.mark.parametrize("command", ["run", "demo"])
def test_each_node_says_what_it_counted_when_it_stops(command, tmp_path):
    """Issue 29, item 13: the README said the counters are in "each node's stop line";
    Ctrl-C printed none (they were logged at INFO, shown only with -v)."""
    show = tmp_path / "show.toml"
    show.write_text('[nodes.robot]\nadapter = "sim"\nrobot = "pepper9"\n\n'
                    '[nodes.sound]\nadapter = "osc"\nsubscribe = "pepper9/joints/*"\n'
                    f'targets = ["127.0.0.1:{free_port(socket.SOCK_DGRAM)}"]\n')
    argv = ["run", str(show)] if command == "run" else ["demo", "--quiet", "--robot", "pepper9",
                                                         "--port", str(free_port(socket.SOCK_DGRAM))]
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    status: list[int] = []
    thread = threading.Thread(target=lambda: status.append(
        main([*argv, "--no-multicast", "--listen", f"tcp/127.0.0.1:{free_port()}"], env)))
    thread.start()
    try:
        wait_for(lambda: "sonibus: running " in env.stdout.getvalue() or not thread.is_alive(), timeout=30,
                 what="the nodes running")
    finally:
        env.stop.set()
        thread.join(10)
    lines = {m[1]: m[3] for m in re.finditer(r"^sonibus: stopped (\w+) \((\w+)\): (.*)$", env.stdout.getvalue(),
                                             re.MULTILINE)}
    assert lines.keys() == {"robot", "sound"}, env.stdout.getvalue() + env.stderr.getvalue()
    counted = dict(re.findall(r"(\w+) ([\d,]+)", lines["sound"]))
    assert {"received", "sent", "dropped", "stale", "bad", "errors"} <= counted.keys(), lines["sound"]
    assert "sonibus: INFO" not in env.stderr.getvalue(), "at the default level, not with -v"


# -- item 7: sonibus is on no package index ----------------------------------------------------


def test_no_message_tells_users_to_install_sonibus_from_the_package_index(tmp_path):
    """Issue 29, item 7: docs and the ros2 adapter's errors said `pip install 'sonibus[ros2]'`;
    pip answers `from versions: none` (and would install someone else's package were the
    name ever taken). A missing extra is named with where sonibus was installed from."""
    lies = [f"{path.relative_to(ROOT)}:{n}" for folder in ("bus", "adapters") for path in (ROOT / folder).rglob("*.py")
            for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
            if re.search(r"install ['\"]sonibus\[", line)]
    assert not lies
    code = "from sonibus.bus import registry; print(registry.install_extra('ros2-dds', 'ros2'))"
    shown = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert shown.stdout.strip() == f"pip install -e '{ROOT}[ros2-dds]'", shown  # (make setup: an editable install)


# -- docs/naoqi.md: the first connection's lines ---------------------------------------------


def naoqi_doc_line(start: str) -> str:
    """The line of docs/naoqi.md's first-connection checklist that starts with ``start``."""
    text = (ROOT / "docs" / "naoqi.md").read_text(encoding="utf-8")
    checklist = text.partition("## First connection to a real Pepper")[2].partition("\n## ")[0]
    return next(line.strip().removeprefix("- `").split("`:")[0] for line in checklist.splitlines()
                if line.strip().removeprefix("- `").startswith(start))


def test_the_first_connection_says_what_docs_naoqi_says_it_says(net, spawn, tmp_path):
    """The line that says it worked, and the one of a robot that does not answer, as
    `sonibus run` prints them at the default level (against the fake robot)."""
    url = f"tcp://127.0.0.1:{free_port()}"
    show = tmp_path / "pepper.toml"
    show.write_text(f'[nodes.fake]\nadapter = "naoqi-sim"\nlisten = "{url}"\nrobot_name = "Juliette"\n\n'
                    f'[nodes.pepper]\nadapter = "naoqi"\nurl = "{url}"\n')
    robot = spawn(SONIBUS, "run", str(show), *net.cli_args(), collect=True, merge=True)
    said = naoqi_doc_line("sonibus: INFO: pepper: connected to").replace("tcp://192.168.1.20:9559", url)
    wait_for(lambda: said in robot.lines, timeout=30, what=f"the line {said!r}", explain=lambda: "\n".join(robot.lines))
    assert robot.stop()[0] == 130

    closed = f"tcp://127.0.0.1:{free_port()}"  # (nothing listens there)
    show.write_text(f'[nodes.pepper]\nadapter = "naoqi"\nurl = "{closed}"\n')
    robot = spawn(SONIBUS, "run", str(show), *net.cli_args(), collect=True, merge=True)
    said = naoqi_doc_line("sonibus: WARNING: pepper: robot 'pepper' is unreachable").replace(
        "tcp://192.168.1.20:9559", closed)
    wait_for(lambda: said in robot.lines, timeout=30, what=f"the line {said!r}", explain=lambda: "\n".join(robot.lines))
    assert robot.stop()[0] == 130
