"""``sonibus run`` says where it and each of its nodes are reached: the bus with the port
it really bound (also a listen on port 0), the OSC targets, pages, ports."""

from __future__ import annotations

import re

from .conftest import SONIBUS, free_port, run_cli, wait_for


def test_the_bus_port_printed_is_the_one_bound_and_joinable(spawn, tmp_path):
    osc = free_port()
    show = tmp_path / "show.toml"
    show.write_text('[bus]\nmulticast = false\nlisten = ["tcp/127.0.0.1:0"]\n\n'
                    '[nodes.pepper]\nadapter = "sim"\nrate_hz = 20\n\n'
                    f'[nodes.sound]\nadapter = "osc"\ntargets = ["127.0.0.1:{osc}", '
                    f'{{ to = "127.0.0.1:{osc + 1}", profile = "pepperosc" }}]\n')
    run = spawn(SONIBUS, "run", str(show), collect=True)
    bus = wait_for(lambda: [line for line in run.lines if line.startswith("sonibus: bus: ")], 20, "the bus line",
                   lambda: "\n".join(run.lines))[0]
    found = re.fullmatch(r"sonibus: bus: peer, multicast off, listening on tcp/127\.0\.0\.1:(\d+) — join from this "
                         r"machine with --connect (tcp/127\.0\.0\.1:\d+) --no-multicast", bus)
    assert found and found[1] != "0" and found[2].endswith(f":{found[1]}"), bus
    assert f"sonibus: sound: OSC to udp 127.0.0.1:{osc} (sonibus), udp 127.0.0.1:{osc + 1} (pepperosc)" in run.lines

    nodes = run_cli("nodes", "--no-multicast", "--connect", found[2])
    assert nodes.returncode == 0 and re.search(r"node\s+pepper\s", nodes.stdout), nodes.stdout + nodes.stderr
    code, _, err = run.stop()
    assert code == 130, err


def test_a_peers_default_listen_is_printed_with_its_port(spawn, tmp_path):
    """No listen in the file: Zenoh listens on tcp/[::]:0, a port nobody could guess before."""
    show = tmp_path / "show.toml"
    show.write_text('[bus]\nmulticast = false\n\n[nodes.pepper]\nadapter = "sim"\nrate_hz = 20\n')
    run = spawn(SONIBUS, "run", str(show), collect=True)
    bus = wait_for(lambda: [line for line in run.lines if line.startswith("sonibus: bus: ")], 20, "the bus line")[0]
    found = re.search(r"listening on tcp/\[::\]:(\d+) — join from this machine with --connect (tcp/\[::1\]:\d+) ",
                      bus)
    assert found and found[1] != "0", bus
    sent = run_cli("send", "pepper", "stop", "--no-multicast", "--connect", found[2])
    assert sent.returncode == 0, sent.stderr
    run.stop()
