"""A restarted show says so: the count (systemd's $NRESTARTS, or sonibus's state file
where there is no systemd), how the run before ended, in every node's stats and as a
``node`` event with state ``restarted``."""

from __future__ import annotations

import os
import re

from sonibus.bus import decode, health, keys
from sonibus.bus.restarts import STOPPED, RunState

from .conftest import SONIBUS, run_cli, wait_for


def test_a_run_after_a_failed_one_is_a_restart_in_its_stats_its_event_and_nodes(net, spawn, tmp_path):
    """The test is the supervisor here (a shell loop would be): it starts the show again."""
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmulticast = false\nconnect = ["{net.endpoint}"]\n\n'
                    f'[nodes.lines]\nadapter = "jsonl"\npath = "{tmp_path / "lines.jsonl"}"\n')
    env = {k: v for k, v in os.environ.items() if k not in ("NRESTARTS", "STATE_DIRECTORY")}
    env["XDG_STATE_HOME"] = str(tmp_path / "state")
    events = []
    watcher = net.bus("watcher")
    watcher.session.declare_subscriber(keys.NODE_EVENTS, lambda s: events.append(decode(s.payload.to_bytes())))
    script = net.bus("script").session.declare_publisher("pepper/joints/HeadYaw")

    first = spawn(SONIBUS, "run", str(show), env=env, collect=True)
    wait_for(lambda: script.matching_status.matching, 20, "the sink's subscription")
    script.put(b"\xc1 not msgpack")  # its worker dies: the process ends with 1, for its supervisor to restart
    wait_for(lambda: first.popen.poll() is not None, 10, "the first run to end")
    assert first.popen.returncode == 1
    assert not any("restart" in line for line in first.lines), first.lines

    second = spawn(SONIBUS, "run", str(show), env=env, collect=True)
    wait_for(lambda: [e for e in events if e["state"] == "restarted"], 20, "the restarted event",
             lambda: "\n".join(second.lines))
    reason = "failed: node 'lines': worker 'write' failed: DecodeError: payload is not msgpack"
    restarted = next(e for e in events if e["state"] == "restarted")
    assert restarted | {"t": 0} == {"t": 0, "kind": "node", "host": watcher.host, "node": "lines", "adapter": "jsonl",
                                    "state": "restarted", "restarts": 1, "previous": restarted["previous"]}
    assert restarted["previous"].startswith(reason), restarted
    said = wait_for(lambda: [line for line in second.lines if "running lines" in line], 10, "the running line")
    assert re.search(r"restart 1 \(counted in .*state/sonibus/show-.*\.json\); the previous run failed: node "
                     r"'lines'", said[0]), said
    stats = wait_for(lambda: health.latest(watcher).get((watcher.host, "lines")), 10, "the node's stats")
    assert stats["process"]["restarts"] == 1, stats
    nodes = run_cli("nodes", *net.cli_args())
    assert re.search(r"lines .*\n.* restarts 1$", nodes.stdout, re.M), nodes.stdout

    code, _, err = second.stop()
    assert code == 130, err
    assert [e["state"] for e in events] == ["failed", "restarted"]


def test_systemd_counts_the_restarts_and_the_state_file_tells_how_the_last_run_ended(tmp_path):
    def begin(**env: str):
        return RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": str(tmp_path), **env}).begin()

    assert begin(NRESTARTS="0").count == 0
    killed = begin(NRESTARTS="3")  # the first run never wrote its end: killed, crashed, or the watchdog's SIGABRT
    assert (killed.count, killed.source) == (3, "systemd's $NRESTARTS")
    assert re.fullmatch(r"\(pid \d+, started [-\d: ]+\) ended without a word: killed, crashed, or stopped by a "
                        r"watchdog \(see its log\)", killed.previous), killed.previous
    assert str(killed).startswith("restart 3 (systemd's $NRESTARTS); the previous run (pid ")

    state = RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": str(tmp_path)})
    assert state.begin().count == 4  # no systemd: the file's count goes on from the unended run's 3
    state.end(STOPPED)
    assert begin() == begin().__class__(0, "", f"counted in {state.path}")  # a clean stop: counted from 0 again


def test_another_host_or_selection_of_the_same_file_keeps_its_own_count(tmp_path):
    env = {"STATE_DIRECTORY": str(tmp_path)}
    RunState.for_run("show.toml", "stage", environ=env).begin()  # never ended
    assert RunState.for_run("show.toml", "stage", environ=env).begin().count == 1
    assert RunState.for_run("show.toml", "sound", environ=env).begin().count == 0
    assert RunState.for_run("show.toml", "stage", ["web"], environ=env).begin().count == 0


def test_a_state_folder_that_cannot_be_written_is_one_warning_and_the_run_goes_on(tmp_path, caplog):
    blocked = tmp_path / "file"
    blocked.write_text("")
    restart = RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": str(blocked)}).begin()
    assert restart.count == 0
    (record,) = caplog.records
    assert record.getMessage().startswith(f"cannot write the run state {blocked}/show-stage-")
    assert "restarts are not counted here (set STATE_DIRECTORY or XDG_STATE_HOME to a writable folder)" in \
        record.getMessage()
