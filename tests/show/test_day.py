"""Issue 25, item 1 and its first Done-when: examples/museum.toml, changed in its one
robot line, plays a compressed day against naoqi-sim (fake NAOqi services on a real
libqi session, in a process of its own) and sends the robot the same commands as
the file unchanged does on the simulator.

Each day runs in a network namespace of its own (the file's fixed ports and
multicast stay inside it), both at once, with ``sonibus rehearse`` (the show's
clock 600× faster, a Tuesday from 09:59): opening, idle gestures with rests, a
scenario from the kiosk (its WebSocket protocol) and one from OSC (UDP, python-osc),
the robot lost mid-scenario (its process stopped: SIGSTOP) and back (SIGCONT),
closing. A witness on the bus (``visitor.py``) sees every event; the owner's
``command`` events are what the robot executed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonibus.bus import config

from ..conftest import SONIBUS, wait_for
from ..net.netns import Host, NsProcess, Topology

ROOT = Path(__file__).resolve().parents[2]
MUSEUM = ROOT / "examples" / "museum.toml"
VISITOR = Path(__file__).with_name("visitor.py")
SPEED = 600                      # 8 opening hours in 48 s
FROM = "2025-06-03 09:59"        # a Tuesday, a minute before opening
STEP_S = 40.0                    # the longest any one step of the day may take (a loaded machine)
SKY, HEY = "animations/Stand/Gestures/ShowSky_1", "animations/Stand/Gestures/Hey_1"
NAOQI_URL = "tcp://127.0.0.1:9559"
REST, AWAKE = {"names": ["Body"], "value": 0.0}, {"names": ["Body"], "value": 1.0}  # stiffness off, on


def museum_on_naoqi() -> str:
    """museum.toml with the one line its comment names replaced by the line it gives."""
    text = MUSEUM.read_text(encoding="utf-8")
    given = next(line.strip().removeprefix("#").strip() for line in text.splitlines()
                 if line.strip().startswith("#") and 'adapter = "naoqi"' in line)
    line = next(line for line in text.splitlines() if line.startswith("robot = { adapter = "))
    return text.replace(line, given.replace("tcp://<robot ip>:9559", NAOQI_URL))


@dataclass
class Day:
    """One compressed day in ``host``'s namespace, its files in ``folder``."""

    topology: Topology
    host: Host
    folder: Path
    naoqi: bool
    processes: dict[str, NsProcess] = field(default_factory=dict)
    failure: BaseException | None = None

    def start(self, name: str, *args: str, **kwargs: Any) -> NsProcess:
        process = NsProcess(self.host.command(*args), cwd=self.folder, **kwargs)
        self.processes[name] = self.topology.track(process)
        return process

    # -- what the witness saw ------------------------------------------------------------------

    def records(self) -> list[dict[str, Any]]:
        out = []
        for line in list(self.processes["visitor"].lines):
            try:
                out.append(json.loads(line))
            except ValueError:
                continue
        return out

    def events(self, kind: str = "", **fields: Any) -> list[tuple[int, dict[str, Any]]]:
        """(place in the record, event) of the events of ``kind`` with ``fields``."""
        return [(i, r["event"]) for i, r in enumerate(self.records()) if "event" in r
                and kind in ("", r["event"]["kind"]) and all(r["event"].get(k) == v for k, v in fields.items())]

    def first(self, kind: str, after: int = -1, what: str = "", **fields: Any) -> tuple[int, dict[str, Any]]:
        """The first event of ``kind`` with ``fields`` after place ``after``, waited for."""
        return wait_for(lambda: next(((i, e) for i, e in self.events(kind, **fields) if i > after), None),
                        STEP_S, f"{self.name}: {what or kind} {fields}", self.describe)

    def commands(self) -> list[tuple[str, dict[str, Any]]]:
        """What the robot's owner executed, in order."""
        return [(e["verb"], e["args"]) for _, e in self.events("command") if e["ok"]]

    def tell(self, line: str) -> dict[str, Any]:
        """A line to the visitor; its answer."""
        before = len(self.records())
        visitor = self.processes["visitor"].popen
        visitor.stdin.write(line + "\n")
        visitor.stdin.flush()
        return wait_for(lambda: next((r for r in self.records()[before:] if {"pressed", "osc", "error"} & set(r)),
                                     None), STEP_S, f"{self.name}: the answer to '{line}'", self.describe)

    @property
    def name(self) -> str:
        return "naoqi day" if self.naoqi else "sim day"

    def describe(self) -> str:
        return "\n".join(f"{name}: {p.describe()}" for name, p in self.processes.items())

    # -- the day ------------------------------------------------------------------------------------

    def play(self) -> None:
        try:
            self._play()
        except BaseException as exc:  # (pytest.fail too: raised again by the test's thread)
            self.failure = exc

    def _play(self) -> None:
        museum = self.folder / "museum.toml"
        museum.write_text(museum_on_naoqi() if self.naoqi else MUSEUM.read_text(encoding="utf-8"))
        nodes = config.load(museum).nodes
        web, gateway = nodes["kiosk"].options, nodes["gateway"].options
        kiosk = f"ws://{web['listen']}/kiosk/ws?token={web['kiosk_token']}"
        self.start("visitor", sys.executable, str(VISITOR), "--kiosk", kiosk, "--gateway", gateway["listen"],
                   stdin=subprocess.PIPE, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        wait_for(lambda: {"ready": True} in self.records(), STEP_S, "the witness's session", self.describe)
        rehearse = [SONIBUS, "rehearse", str(museum), "--from", FROM, "--speed", str(SPEED)]
        if self.naoqi:  # the robot: fake NAOqi services in a process of their own
            fake = self.folder / "fake.toml"
            fake.write_text(f'[nodes.fake]\nadapter = "naoqi-sim"\nlisten = "{NAOQI_URL}"\nrate_hz = 50\n')
            robot = self.start("robot", SONIBUS, "run", str(fake), "--no-multicast")
            wait_for(lambda: any("running fake" in line for line in robot.lines), STEP_S, "naoqi-sim", self.describe)
            self.start("museum", *rehearse)
        else:  # the robot: the file's own sim node, in a process of its own so that it can be lost
            robot = self.start("robot", SONIBUS, "run", str(museum), "--only", "robot")
            wait_for(lambda: any("running robot" in line for line in robot.lines), STEP_S, "the sim", self.describe)
            self.start("museum", *rehearse, "--only", *[n for n in nodes if n != "robot"])
        opened, _ = self.first("show", state="open", what="the opening")
        second = wait_for(lambda: [i for i, _ in self.events("command", verb="behavior/run") if i > opened][1:],
                          STEP_S, f"{self.name}: two idle gestures", self.describe)[0]
        pressed = self.tell("press hello")
        assert pressed.get("reply", {}).get("ok"), f"{self.name}: kiosk press: {pressed}"
        ended, _ = self.first("scenario", second, name="hello", state="ended")
        idle, _ = self.first("command", ended, what="an idle gesture", verb="behavior/run")
        sent = self.tell("osc story")
        assert sent.get("reply", [None, 0])[:2] == ["/pepper/reply/scenario", 1], f"{self.name}: OSC: {sent}"
        started, _ = self.first("scenario", idle, name="story", state="started")
        self.first("command", started, what="the story's behavior", verb="behavior/run", args={"name": SKY})
        os.kill(robot.popen.pid, signal.SIGSTOP)  # the robot stops answering: its process is frozen
        try:
            aborted, _ = self.first("scenario", started, name="story", state="aborted")
        finally:
            os.kill(robot.popen.pid, signal.SIGCONT)
        back, _ = self.first("command", aborted, what="the robot taken again", verb="posture",
                             args={"name": "StandInit"})
        closed, _ = self.first("show", back, state="closed", what="the closing")
        self.first("command", closed, what="the robot at rest", verb="stiffness", args=REST)
        code, _, _ = self.processes["museum"].stop()
        assert code == 130, f"{self.name}: the museum ended with {code}: {self.describe()}"


def segments(commands: list[tuple[str, dict[str, Any]]]) -> tuple[list[Any], list[Any], list[Any]]:
    """The commands before the last stretch of idle gestures (up to the robot taken again after
    its loss), that stretch, and what follows it (the closing): how many gestures fit in the
    stretch depends on how fast the machine is, not on the show."""
    back = max(i for i, c in enumerate(commands) if c == ("posture", {"name": "StandInit"}))
    rest = next(i for i, c in enumerate(commands) if i > back and c[0] != "behavior/run")
    return commands[:back + 1], commands[back + 1:rest], commands[rest:]


def test_museum_toml_changed_in_one_line_plays_the_same_day_on_naoqi_sim_as_on_the_sim(topology, tmp_path,
                                                                                          figure):
    sim_host, = topology.lan("simday")
    naoqi_host, = topology.lan("naoday")
    days = []
    for host, naoqi in ((sim_host, False), (naoqi_host, True)):
        folder = tmp_path / host.name
        folder.mkdir()
        days.append(Day(topology, host, folder, naoqi))
    sound = naoqi_host.oscdump(9000)  # the sound patch of the real-robot file: museum.toml's OSC target
    threads = [threading.Thread(target=day.play, name=day.name) for day in days]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for day in days:
        if day.failure is not None:
            raise day.failure
    sim_day, naoqi_day = days

    for day in days:
        commands = day.commands()
        head, _, tail = segments(commands)
        assert head[:5] == [("stop", {}), ("posture", {"name": "Crouch"}), ("stiffness", REST),
                            ("stiffness", AWAKE), ("posture", {"name": "StandInit"})], \
            f"{day.name}: taken at rest before 10:00, woken at opening: {head[:5]}"
        assert ("say", {"text": "Hello!"}) in head and ("behavior/run", {"name": HEY}) in head
        assert head[-5:] == [("say", {"text": "Look up there."}), ("behavior/run", {"name": SKY}), ("stop", {}),
                             ("stiffness", AWAKE), ("posture", {"name": "StandInit"})], \
            f"{day.name}: the story cut at its behavior, nothing resumed, the robot stopped and made ready: {head[-5:]}"
        assert tail == [("posture", {"name": "Crouch"}), ("stiffness", REST)]
        scenarios = [(e["name"], e["state"], e.get("by")) for _, e in day.events("scenario")]
        assert scenarios == [("hello", "started", "kiosk"), ("hello", "ended", "kiosk"),
                             ("story", "started", "osc"), ("story", "aborted", "osc")], f"{day.name}: {scenarios}"
        assert "lost" in day.events("scenario", state="aborted")[0][1]["reason"]
        rests = idle_rests(day)
        assert rests and min(rests) >= 120 / SPEED, f"{day.name}: idle gestures closer than their rest: {rests}"
        figure(f"{day.name}: idle gestures", len(rests) + 1)
        figure(f"{day.name}: shortest rest between idle gestures", min(rests) * SPEED, "show s")

    sim_head, sim_idle, sim_tail = segments(sim_day.commands())
    naoqi_head, naoqi_idle, naoqi_tail = segments(naoqi_day.commands())
    assert naoqi_head == sim_head, "the same commands up to the last stretch of idle gestures"
    shorter = min(len(sim_idle), len(naoqi_idle))
    assert sim_idle[:shorter] == naoqi_idle[:shorter], "the same idle gestures in the same order"
    assert naoqi_tail == sim_tail

    heard = [(m.address, m.args) for m in sound.messages("/pepper/events/s")]
    for address, state in (("/pepper/events/show", '"open"'), ("/pepper/events/scenario", '"started"'),
                           ("/pepper/events/scenario", '"ended"'), ("/pepper/events/scenario", '"aborted"'),
                           ("/pepper/events/show", '"closed"')):
        assert any(a == address and state in args for a, args in heard), f"{address} {state} not heard: {heard}"


def idle_rests(day: Day) -> list[float]:
    """Real seconds from the end of each idle gesture to the start of the next one."""
    gaps, ended = [], None
    scenario = False
    for _, event in day.events():
        if event["kind"] == "scenario":
            scenario = event["state"] == "started"
            ended = None
        elif event["kind"] == "behavior" and event["state"] == "stopped" and not scenario:
            ended = event["t"]
        elif event["kind"] == "command" and event["verb"] == "behavior/run" and not scenario:
            if ended is not None:
                gaps.append(event["t"] - ended)
            ended = None
        elif event["kind"] in ("show", "connection") or event["kind"] == "command":  # (another command between)
            ended = None
    return gaps

