"""Issue 14, item 2: examples/three-machines.toml, as shipped (multicast, user and
password, the robot's access control), works in all six start orders of its
three machines and after any of them restarts: the sound machine receives the
robot's joints, the control machine's commands run, the sound machine's are refused.

Three network namespaces on one LAN with real multicast; each machine runs
`sonibus run three-machines.toml --host NAME` from a copy of the example folder.
The set-up is shared by the tests of this module (they run in order)."""

from __future__ import annotations

import itertools
import json
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from .netns import Host, NsProcess, OscDump, Topology
from .test_multihost import joint, until
from .test_silence import SILENCE

pytestmark = pytest.mark.external

EXAMPLES = Path(__file__).parents[2] / "examples"
ROLES = ("robot", "sound", "control")
HOSTS = {"robot": "robot-laptop", "sound": "sound-pc", "control": "control-pc"}
GAP_S = 1.5          # between two machines switched on
FIRST_DATA_S = 5.0   # the bound: data at the sound machine after the last machine starts
REFUSAL = "access control on the robot's machine refuses commands from this machine (user 'sound')"


@dataclass
class Museum:
    """The three machines of the example and what runs on them."""

    topology: Topology
    hosts: dict[str, Host]
    path: str
    dump: OscDump
    runs: dict[str, NsProcess] = field(default_factory=dict)

    def start(self, role: str) -> float:
        """``sonibus run`` on ``role``'s machine; the time it was started."""
        started = time.time()
        self.runs[role] = self.hosts[role].sonibus("run", self.path, "--host", HOSTS[role])
        return started

    def stop(self, role: str, sig: int = signal.SIGINT) -> None:
        process = self.runs.pop(role, None)
        if process is None:
            return
        if sig == signal.SIGKILL:
            process.kill()
        else:
            process.stop(sig)

    def stop_all(self) -> None:
        for role in list(self.runs):
            self.stop(role)

    def first_data(self, since: float, timeout: float = FIRST_DATA_S + 5) -> float:
        """Seconds from ``since`` to the first HeadYaw sample at the sound machine (oscdump's
        stamp: when this busy process reads oscdump's output is not the installation's)."""
        found = until(self.topology, lambda: joint(self.dump, since=since), timeout,
                      "HeadYaw at the sound machine")
        return found[0].received - since

    def send(self, role: str, *command: str) -> subprocess.CompletedProcess[str]:
        return self.hosts[role].cli("send", "pepper", *command, "--config", self.path, "--host", HOSTS[role])

    def commands_seen(self, since: float) -> list[str]:
        """The ``command`` events the sound machine forwarded since ``since`` (their arguments)."""
        return [m.args for m in self.dump.messages("/pepper/events/command") if m.read >= since]


@pytest.fixture(scope="module")
def museum(shared_topology: Topology, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Museum]:
    hosts = dict(zip(ROLES, shared_topology.lan(*ROLES), strict=True))
    folder = tmp_path_factory.mktemp("museum")
    for name in ("three-machines.toml", "users.txt"):
        shutil.copy(EXAMPLES / name, folder / name)
    place = Museum(shared_topology, hosts, str(folder / "three-machines.toml"), hosts["sound"].oscdump())
    try:
        yield place
    finally:
        place.stop_all()


def check_commands(museum: Museum, angle: float) -> None:
    """Control's command runs (once), sound's is refused by the robot's access control."""
    asked = time.time()
    done = museum.send("control", "joints/set", "names=HeadYaw", f"angles={angle}", "speed=1.0")
    assert done.returncode == 0, f"control's command: exit {done.returncode}: {done.stderr}\n{museum.topology.report()}"
    assert json.loads(done.stdout)["targets"] == {"HeadYaw": angle}
    refused = museum.send("sound", "joints/set", "names=HeadYaw", "angles=-1.0", "speed=1.0")
    assert refused.returncode == 4, f"sound's command: exit {refused.returncode}: {refused.stdout} {refused.stderr}"
    assert REFUSAL in refused.stderr
    events = until(museum.topology, lambda: museum.commands_seen(asked), 5.0, "the command event at sound")
    time.sleep(0.3)  # a second event, had the command run twice
    events = museum.commands_seen(asked)
    assert events == ['si "joints/set" 1'], events  # the OSC form of one executed joints/set


@pytest.mark.parametrize("order", list(itertools.permutations(ROLES)), ids="-".join)
def test_any_start_order(museum, order, figure):
    museum.stop_all()
    for index, role in enumerate(order):
        if index:
            time.sleep(GAP_S)
        last = museum.start(role)
    first = museum.first_data(last)
    figure(f"first data at sound after the last machine ({order[-1]}) started", first, "s")
    assert first <= FIRST_DATA_S, f"data reached the sound machine {first:.2f} s after the last machine started"
    check_commands(museum, 0.25)
    for process in museum.runs.values():
        assert process.running, process.describe()
    assert not [line for line in museum.runs["sound"].errors if SILENCE in line], "a healthy installation warned"


@pytest.mark.parametrize("role", ROLES)
def test_each_machine_restarts(museum, role, figure):
    """In turn, after the start orders: the robot's laptop switched off hard (SIGKILL),
    the others stopped; each started again, the installation works again."""
    for other in ROLES:
        if other not in museum.runs:
            museum.start(other)
    museum.first_data(time.time())
    museum.stop(role, signal.SIGKILL if role == "robot" else signal.SIGINT)
    time.sleep(GAP_S)
    again = museum.start(role)
    first = museum.first_data(again)
    figure(f"first data at sound after {role} restarted", first, "s")
    assert first <= FIRST_DATA_S, f"data reached the sound machine {first:.2f} s after {role} restarted"
    check_commands(museum, -0.2)
    assert not [line for line in museum.runs["sound"].errors if SILENCE in line], "a healthy installation warned"
