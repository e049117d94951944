"""Install like a package (issue 19): a wheel built from the repo (not editable),
installed with its dependencies but without the ``naoqi`` extra into a clean
virtualenv, runs every command with all its data files; shell completion answers
from the README's one-line set-up.

The wheel is built from a copy of the tree (a fresh build: setuptools' ``build/``
keeps files that were deleted), and installed once for the module."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
import urllib.request
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from .conftest import Process, free_port, wait_for

# pip and a package index are outside tools; the first test also pays for the install
pytestmark = [pytest.mark.external, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
COMMANDS = sorted(PROJECT["entry-points"]["sonibus.commands"])
ADAPTERS = sorted(PROJECT["entry-points"]["sonibus.adapters"])
# where each package's files are in the tree ([tool.setuptools] package-dir)
SOURCES = {"sonibus/bus": ROOT / "bus", "sonibus/adapters": ROOT / "adapters", "sonibus/schemas": ROOT / "schemas"}
NOT_COPIED = shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis")
NOT_SHIPPED = re.compile(r"__pycache__|\.pyc$")
ONE_LINER = 'eval "$(register-python-argcomplete sonibus)"'  # shell completion's set-up


@dataclass(frozen=True)
class Installed:
    """The clean virtualenv with the wheel installed, and how to run its commands."""

    wheel: Path
    venv: Path
    work: Path  # the working folder of every command run here (not the repo)
    seconds: float  # to build the wheel, make the virtualenv and install

    @property
    def env(self) -> dict[str, str]:
        env = {name: value for name, value in os.environ.items()
               if name not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME")}
        return {**env, "PATH": f"{self.venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"}

    @property
    def sonibus(self) -> str:
        return str(self.venv / "bin" / "sonibus")

    def run(self, *args: str, timeout: float = 30.0, **changes: str) -> subprocess.CompletedProcess[str]:
        """``sonibus ARGS`` to completion in the virtualenv."""
        return subprocess.run([self.sonibus, *args], capture_output=True, text=True, timeout=timeout,
                              cwd=self.work, env={**self.env, **changes})

    def start(self, spawn: Callable[..., Process], *args: str) -> Process:
        """``sonibus ARGS`` in the background, its stdout and stderr lines collected."""
        return spawn(self.sonibus, *args, collect=True, merge=True, cwd=self.work, env=self.env)


def _done(args: list[str], what: str, timeout: float, **kwargs: object) -> None:
    result = subprocess.run(args, capture_output=True, text=True, timeout=timeout, **kwargs)
    if result.returncode != 0:
        pytest.fail(f"{what} failed ({result.returncode}): {' '.join(args)}\n{result.stderr[-3000:]}")


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    base = tmp_path_factory.mktemp("wheel")
    began = time.monotonic()
    source = base / "source"
    shutil.copytree(ROOT, source, ignore=NOT_COPIED)
    dist = base / "dist"
    _done([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), "."], "pip wheel", 300,
          cwd=source)
    wheel = next(dist.glob("sonibus-*.whl"))
    venv = base / "venv"
    _done([sys.executable, "-m", "venv", str(venv)], "python -m venv", 120)
    _done([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", str(wheel)], "pip install", 500)
    work = base / "work"
    work.mkdir()
    return Installed(wheel, venv, work, time.monotonic() - began)


def test_the_wheel_holds_every_module_and_data_file_of_the_tree(installed, figure):
    figure("wheel built, clean virtualenv made and installed", installed.seconds, "s")
    shipped = set(zipfile.ZipFile(installed.wheel).namelist())
    tree = sorted(f"{package}/{path.relative_to(folder)}" for package, folder in SOURCES.items()
                  for path in folder.rglob("*") if path.is_file() and not NOT_SHIPPED.search(str(path)))
    missing = [name for name in tree if name not in shipped]
    assert not missing, (f"not in the wheel: {', '.join(missing)} — add the package to [tool.setuptools] packages "
                         f"or its files to [tool.setuptools.package-data] in pyproject.toml")


def test_version_is_the_installed_distributions_and_sonibus_is_the_wheels(installed):
    result = installed.run("--version")
    assert (result.returncode, result.stdout, result.stderr) == (0, f"sonibus {PROJECT['version']}\n", "")
    code = "import sonibus.bus; print(sonibus.bus.__file__)"
    where = subprocess.run([str(installed.venv / "bin" / "python"), "-c", code], capture_output=True, text=True,
                           timeout=30, cwd=installed.work, env=installed.env)
    assert Path(where.stdout.strip()).is_relative_to(installed.venv), where  # not the repo: no editable install


def test_adapters_names_what_the_naoqi_extra_adds_and_warns_about_nothing(installed):
    result = installed.run("adapters")
    assert (result.returncode, result.stderr) == (0, ""), result.stderr
    listed = dict(line.split(maxsplit=1) for line in result.stdout.splitlines())
    assert sorted(listed) == ADAPTERS  # every adapter of the wheel, and nothing of the test plug-in
    wheel = re.escape(str(installed.wheel))  # what to install names the wheel it came from (not on PyPI)
    lacking = {name: re.fullmatch(rf"\(not installed: pip install '{wheel}\[(\w+)\]'\)", text)
               for name, text in listed.items()}
    extras = {name: match.group(1) for name, match in lacking.items() if match}
    assert extras.get("naoqi") == extras.get("naoqi-sim") == "naoqi", listed
    assert set(extras.values()) <= set(PROJECT["optional-dependencies"]) - {"test"}, extras
    assert not {"sim", "osc", "osc-gateway", "console", "recorder", "replay", "features"} & set(extras), extras


def test_every_command_has_help_and_says_nothing_on_stderr(installed):
    top = installed.run("--help")
    assert (top.returncode, top.stderr) == (0, ""), top.stderr
    assert "--version" in top.stdout
    assert all(re.search(rf"^\s+{re.escape(name)}\s", top.stdout, re.M) for name in COMMANDS), top.stdout
    for name in COMMANDS:
        result = installed.run(name, "--help")
        assert (result.returncode, result.stderr) == (0, ""), f"sonibus {name} --help: {result.stderr}"
        assert result.stdout.startswith(f"usage: sonibus {name} "), result.stdout


def _interrupted(process: Process) -> tuple[int, str]:
    """Ctrl-C: its exit status, and all it said (stdout and stderr)."""
    status, rest, _ = process.stop(signal.SIGINT, timeout=15)
    return status, "\n".join([*process.lines, rest])


def _receive(sock: socket.socket, prefix: bytes) -> bytes:
    """The first datagram that starts with ``prefix`` (the socket's timeout bounds each wait)."""
    while not (packet := sock.recv(65536)).startswith(prefix):
        pass
    return packet


@pytest.fixture
def osc_receiver():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(30)
        yield sock


def test_demo_sends_osc_and_ends_on_ctrl_c_with_130(installed, spawn, osc_receiver):
    demo = installed.start(spawn, "demo", "--quiet", "--no-multicast", "--port", str(osc_receiver.getsockname()[1]),
                           "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert _receive(osc_receiver, b"/pepper/joints/")
    status, said = _interrupted(demo)
    assert status == 130 and "Traceback" not in said, said


def _example(installed: Installed, name: str, *changes: tuple[str, str]) -> Path:
    """A shipped example as a user would adapt it: a copy with some lines changed."""
    text = (ROOT / "examples" / name).read_text(encoding="utf-8")
    for old, new in changes:
        assert old in text, f"examples/{name} no longer has {old!r}"
        text = text.replace(old, new)
    path = installed.work / name
    path.write_text(text, encoding="utf-8")
    return path


def test_studio_example_runs_its_robot_is_described_recorded_and_the_recording_read(installed, spawn, osc_receiver):
    port = osc_receiver.getsockname()[1]
    studio = _example(installed, "studio.toml",
                      ('targets = ["127.0.0.1:9000", "127.0.0.1:57120"]', f'targets = ["127.0.0.1:{port}"]'))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    run = installed.start(spawn, "run", str(studio), "--no-multicast", "--listen", endpoint)
    assert _receive(osc_receiver, b"/pepper/joints/")
    bus = ("--no-multicast", "--connect", endpoint)

    info = installed.run("info", "pepper", *bus)
    assert (info.returncode, info.stderr) == (0, ""), info.stderr
    assert re.search(r"^\s+HeadYaw\s+rad\s", info.stdout, re.M), info.stdout  # the live joint table

    recording = installed.work / "studio.mcap"
    record = installed.start(spawn, "record", str(recording), "--status-every", "0.2", *bus)
    counted = re.compile(r"^recording .* (\d+) messages")
    wait_for(lambda: any(int(m.group(1)) >= 100 for line in record.lines if (m := counted.match(line))), 30,
             "a hundred messages recorded", lambda: "\n".join(record.lines))
    for process, expected in ((record, 0), (run, 130)):
        status, said = _interrupted(process)
        assert status == expected and "Traceback" not in said, said

    described = installed.run("info", str(recording), "--json")
    assert (described.returncode, described.stderr) == (0, ""), described.stderr
    summary = json.loads(described.stdout)
    assert summary["robots"]["pepper"]["model"] == "pepper", summary
    assert summary["keys"]["pepper/joints/HeadYaw"]["messages"] > 0, summary
    exported = installed.run("export", str(recording), "--csv", str(installed.work / "csv"))
    assert (exported.returncode, exported.stderr) == (0, ""), exported.stderr
    rows = (installed.work / "csv" / "pepper.csv").read_text(encoding="utf-8").splitlines()
    assert rows[0].startswith("t_s,t_unix_s,seq,HeadYaw,") and len(rows) > 2, rows[:3]

    plotted = installed.run("plot", str(recording))  # matplotlib is the plot extra's: one line saying so
    assert plotted.returncode != 0 and "Traceback" not in plotted.stderr, plotted.stderr
    assert plotted.stderr.startswith("sonibus: error: ") and plotted.stderr.count("\n") == 1, plotted.stderr
    assert "matplotlib" in plotted.stderr


def test_features_example_sends_hand_positions(installed, spawn, osc_receiver):
    port = osc_receiver.getsockname()[1]
    features = _example(installed, "features.toml",
                        ('targets = ["127.0.0.1:57120"]', f'targets = ["127.0.0.1:{port}"]'))
    run = installed.start(spawn, "run", str(features), "--no-multicast", "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert _receive(osc_receiver, b"/pepper/derived/hand/")  # numpy's kinematics, from the wheel's robot table
    status, said = _interrupted(run)
    assert status == 130 and "Traceback" not in said, said


def test_oscquery_example_serves_a_joint_with_its_limits(installed, spawn):
    http, gateway = free_port(), free_port(socket.SOCK_DGRAM)
    oscquery = _example(installed, "oscquery.toml", ('"127.0.0.1:5678"', f'"127.0.0.1:{http}"'),
                        ('"127.0.0.1:9001"', f'"127.0.0.1:{gateway}"'),
                        ("mdns = true", "mdns = false"))  # mDNS names are machine-wide: other tests may hold one
    run = installed.start(spawn, "run", str(oscquery), "--listen", f"tcp/127.0.0.1:{free_port()}")

    def joint() -> dict | None:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{http}/pepper/joints/HeadYaw", timeout=5) as answer:
                return json.load(answer)
        except OSError:
            return None

    node = wait_for(joint, 30, "the OSCQuery node of HeadYaw", lambda: "\n".join(run.lines))
    assert node["RANGE"] == [{"MIN": -2.08567, "MAX": 2.08567}], node
    status, said = _interrupted(run)
    assert status == 130 and "Traceback" not in said, said


def test_completion_offers_commands_from_argcomplete_and_the_readme_one_liner(installed):
    asked = installed.run(_ARGCOMPLETE="1", COMP_LINE="sonibus ad", COMP_POINT="10",
                          _ARGCOMPLETE_STDOUT_FILENAME=str(installed.work / "offered"))  # instead of fd 8
    assert (asked.returncode, asked.stdout, asked.stderr) == (0, "", ""), asked
    assert (installed.work / "offered").read_text().split("\v") == ["adapters "]
    # what argcomplete's global hook (activate-global-python-argcomplete) runs: the marker is found
    marked = subprocess.run([str(installed.venv / "bin" / "python"), "-m", "argcomplete._check_console_script",
                             installed.sonibus], capture_output=True, text=True, timeout=30, env=installed.env)
    assert marked.returncode == 0, marked.stderr
    # the set-up line the README and docs/install.md give, then what bash does on TAB
    for doc in ("README.md", "docs/install.md"):
        assert ONE_LINER in (ROOT / doc).read_text(encoding="utf-8"), doc
    script = (f'{ONE_LINER}; COMP_LINE="sonibus re"; COMP_POINT=10; '
              '_python_argcomplete sonibus re sonibus; printf "%s\\n" "${COMPREPLY[@]}"')
    tab = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=30, cwd=installed.work,
                         env=installed.env)
    assert tab.returncode == 0, tab.stderr
    assert sorted(tab.stdout.split()) == sorted(name for name in COMMANDS if name.startswith("re")), tab.stdout
