"""Issue 26: examples/public-venue.toml, the access control shipped for public venues, as
shipped (multicast, user and password, its rules) on four machines of one LAN: a
stranger's session that logged in (the sound machine's user) cannot claim the robot nor
publish its keys nor answer its commands, one without a password cannot join at all, the
robot's own machine claims and publishes, and stop from the control machine still works
(one robot's, and every robot's at once). Without these rules the same rogue takes the
robot (its claim is an hour earlier: a time that makes sense) and silences it
(docs/design.md, "A rogue on the bus")."""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import pytest

from .netns import Topology
from .test_multihost import joint, started, streaming, until
from .test_private import stop_all

pytestmark = pytest.mark.external

EXAMPLES = Path(__file__).parents[2] / "examples"
ROGUE = str(Path(__file__).with_name("rogue.py"))
HOSTS = {"robot": "robot-laptop", "sound": "sound-pc", "control": "control-pc"}
ANGLE = 2.0  # the rogue's HeadYaw: within the joint's limits, far from the idle robot's


def test_a_rogue_that_logged_in_can_neither_claim_nor_publish_nor_answer_and_stop_works(topology: Topology,
                                                                                          tmp_path):
    robot, sound, control, stranger = topology.lan("robot", "sound", "control", "stranger")
    for name in ("public-venue.toml", "users.txt"):
        shutil.copy(EXAMPLES / name, tmp_path / name)
    path = str(tmp_path / "public-venue.toml")

    def on(role: str) -> list[str]:
        return ["--config", path, "--host", HOSTS[role]]
    dump = sound.oscdump()
    started(topology, robot.sonibus("run", path, "--host", HOSTS["robot"]))
    started(topology, sound.sonibus("run", path, "--host", HOSTS["sound"]))
    streaming(topology, dump)  # the robot's machine claims and publishes; the sound machine hears it

    unknown = stranger.cli("nodes", "--mode", "client", "--no-multicast", "--connect", robot.endpoint(),
                           "--namespace", "venue")
    assert unknown.returncode != 0, f"a session without a password joined: {unknown.stdout}"

    before = time.time()
    rogue = stranger.run(sys.executable, ROGUE, "pepper", "--seconds", "6", "--angle", str(ANGLE), *on("sound"))
    until(topology, lambda: any("rogue" in line or "frames" in line for line in rogue.lines) or
          time.time() > before + 2.5, 10, "the rogue to be under way")
    assert rogue.running, rogue.describe()
    listed = control.cli("nodes", *on("control"))
    assert listed.returncode == 0 and "rogue" not in listed.stdout and "CONFLICT" not in listed.stdout, listed.stdout
    sent = control.cli("send", "pepper", "stop", *on("control"))
    assert sent.returncode == 0 and json.loads(sent.stdout)["held"] is True, f"{sent.stdout} {sent.stderr}"
    stopped = stop_all(control, *on("control"))
    assert stopped["answered"] == {"pepper": "ok"} and stopped["silent"] == [], stopped
    until(topology, lambda: not rogue.running, 20, "the rogue to end")
    said = json.loads(rogue.lines[-1])
    assert said["frames"] > 100 and said["commands_asked"] == [], said  # no command reached its queryable

    during = joint(dump, since=before)
    assert len(during) > 50, f"the robot went silent while the rogue claimed it: {len(during)} samples"
    assert all(abs(m.value - ANGLE) > 0.5 for m in during), "the rogue's frames reached the sound machine"
    stops = [m for m in dump.since(before, "/pepper/events/command") if "stop" in m.args]
    assert len(stops) == 2, f"{len(stops)} stops heard (the control machine sent two)"
