"""The README's two commands: `make demo` installs what users need and ends quietly on
Ctrl-C (issue 19, items 1 and 6); `make test` adds the test plug-in."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
from pathlib import Path

from .conftest import free_port

ROOT = Path(__file__).resolve().parent.parent


def dry_run(target: str) -> str:
    """What ``make TARGET`` would run on a fresh clone (every stamp out of date)."""
    done = subprocess.run(["make", "-n", "-B", target], cwd=ROOT, capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_make_demo_installs_no_test_plugin_and_make_test_does():
    demo = dry_run("demo")
    assert "pip install --quiet -e ." in demo
    assert "tests/plugin" not in demo and "[test]" not in demo
    test = dry_run("test")
    assert "-e tests/plugin" in test and "'.[test]'" in test


def test_ctrl_c_ends_make_demo_without_an_error_from_make():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(30)
        args = f"--quiet --no-multicast --port {receiver.getsockname()[1]} --listen tcp/127.0.0.1:{free_port()}"
        make = subprocess.Popen(["make", "-s", "demo", f"DEMO_ARGS={args}"], cwd=ROOT, start_new_session=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            assert receiver.recv(4096).startswith(b"/pepper/")  # the demo runs
            os.killpg(make.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
            out, _ = make.communicate(timeout=10)
        finally:
            if make.poll() is None:
                os.killpg(make.pid, signal.SIGKILL)
                make.wait()
    assert make.returncode in (0, -signal.SIGINT), out  # make ends by the signal, as Ctrl-C asked
    assert "Error" not in out and "Interrupt" not in out and "Traceback" not in out, out
