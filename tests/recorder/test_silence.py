"""No silent empties: ``sonibus record`` that hears nothing says so and ends
non-zero (3, as when no robot is found), leaving no empty file behind; a
recorder node that hears nothing for ``quiet_warn_s`` warns once, with the
likeliest cause."""

from __future__ import annotations

import logging

from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig

from ..conftest import free_port, run_cli, wait_for


def test_record_with_nothing_reachable_ends_non_zero(tmp_path):
    path = tmp_path / "x.mcap"
    nobody = f"tcp/127.0.0.1:{free_port()}"  # a show it cannot reach
    result = run_cli("record", str(path), "--no-multicast", "--connect", nobody, "--duration", "1")
    assert result.returncode == 3, (result.returncode, result.stdout, result.stderr)
    errors = [line for line in result.stderr.splitlines() if line.startswith("sonibus: error: ")]
    assert len(errors) == 1 and errors[0].startswith("sonibus: error: recorded nothing in "), result.stderr
    assert f"{path} removed" in errors[0] and "*/joints/*" in errors[0], errors
    assert "sonibus: hint: nothing came: this command reached no peer or router" in result.stderr, result.stderr
    assert "recorded " not in result.stdout and not path.exists()


def quiet_lines(caplog):
    return [r.getMessage() for r in caplog.records if "nothing to record for" in r.getMessage()]


def test_a_recorder_that_hears_nothing_warns_once_with_the_likely_cause(net, tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    net.start(Recorder(RecorderConfig(path=str(tmp_path / "a.mcap"), quiet_warn_s=0.5), name="logger"))
    said = wait_for(lambda: quiet_lines(caplog), what="the warning")
    assert "no robot is on the bus" in said[0], said

    net.sim("pepper", rate_hz=50, body_sound=False)
    net.start(Recorder(RecorderConfig(path=str(tmp_path / "b.mcap"), subscribe=("*/derived/**",),
                                      quiet_warn_s=0.5), name="derived"))  # (no features node: nothing derived)
    said = wait_for(lambda: quiet_lines(caplog)[1:], what="the second warning")
    assert "though pepper is on the bus" in said[0] and "subscribe (*/derived/**) selects nothing" in said[0], said
    assert len(quiet_lines(caplog)) == 2, "once each"
