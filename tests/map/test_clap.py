"""Sound to movement, end to end with real parts: a clap (an impulse played into a JACK
input of a dummy-driver server) → the jack node → ``pepper/audio/speaker`` → the hear
node's onset → the map of docs/mapping.md's example → ``joints/set`` → a simulated
Pepper owner on a real Zenoh session, which nods within its limits. During the nod a
stop halts it, and no map moves the robot until ``sonibus resume``."""

from __future__ import annotations

import re
import threading
import time

import jack as jack_client

from sonibus.adapters.hear import Hear
from sonibus.adapters.jack import JackBridge
from sonibus.adapters.map import MapNode
from sonibus.adapters.sim import SimRobot
from sonibus.bus import client, config

from ..conftest import run_cli, wait_for
from ..jackd import jack  # noqa: F401  (the fixture: a private JACK server, dummy driver)
from .conftest import ROOT
from .test_node import Listen
from .test_targets import LIMITS


def nod_example() -> str:
    """The clap-makes-the-robot-nod installation of docs/mapping.md."""
    text = (ROOT / "docs" / "mapping.md").read_text(encoding="utf-8")
    return re.search(r"```toml\n(# examples/clap-nod.toml\n.*?)```", text, re.S)[1]


class Clapper:
    """A JACK client whose output port plays silence, and one impulse when asked."""

    def __init__(self, server: str) -> None:
        self.client = jack_client.Client("clapper", no_start_server=True, servername=server)
        self.port = self.client.outports.register("clap")
        self.clapped: list[float] = []   # wall-clock time of each impulse's block
        self.frames = 0                  # frames played: JACK's clock, which the chunks' times follow
        self._last = -1 << 30            # self.frames at the last impulse
        self._armed = threading.Event()
        self.client.set_process_callback(self._process)
        self.client.activate()

    def _process(self, frames: int) -> None:
        out = self.port.get_array()
        out[:] = 0.0
        if self._armed.is_set():
            self._armed.clear()
            out[0] = 0.9
            self.clapped.append(time.time())
            self._last = self.frames
        self.frames += frames

    def clap(self) -> float:
        """One impulse, 0.3 s of JACK's clock after the last (past the onset's hold, which the hear node
        measures by the chunks' times: a loaded dummy driver runs slower than the wall clock); the
        wall-clock time of the block that played it."""
        wait_for(lambda: self.frames - self._last >= 0.3 * self.client.samplerate, what="0.3 s of JACK's clock")
        count = len(self.clapped)
        self._armed.set()
        wait_for(lambda: len(self.clapped) > count, what="the impulse played")
        return self.clapped[-1]

    def close(self) -> None:
        self.client.deactivate()
        self.client.close()


def built(net, text: str, name: str, adapter: type, **options):
    spec = config.parse(text, "clap-nod.toml").nodes[name]
    spec = config.NodeSpec(spec.name, spec.adapter, {**spec.options, **options}, spec.where, spec.lines)
    return net.start(spec.build(adapter))


def head_moves(listen: Listen, after: float) -> list[float]:
    """HeadPitch of each of pepper's frames since ``after`` (wall clock)."""
    frames = [m for m in listen.on("pepper/frame") if m["t"] >= after]
    return [m["v"][m["names"].index("HeadPitch")] for m in frames]


def sets(listen: Listen) -> list[dict]:
    return [m for m in listen.on("pepper/events/command") if m.get("verb") == "joints/set"]


def test_a_clap_nods_the_robot_and_a_stop_holds_it_until_resumed(net, jack, figure):  # noqa: F811
    text = nod_example()
    clapper = Clapper(jack)
    try:
        watch = net.bus("watch")
        events, frames = Listen(watch, "pepper/events/command"), Listen(watch, "pepper/frame")
        built(net, text, "robot", SimRobot, speaker=False, body_sound=False)
        built(net, text, "jack", JackBridge, connect_inputs=["clapper:clap"])
        ears = built(net, text, "ears", Hear)
        moves: MapNode = built(net, text, "moves", MapNode)
        onset = "pepper/derived/onset/speaker"
        wait_for(lambda: "pepper" in moves._ranges and onset in moves._ranges["pepper"].derived, timeout=10,
                 what="the onset's range from pepper/info/derived")
        low, high = LIMITS["HeadPitch"]

        # a clap: the head goes down to 0.3 (to[1]), within its limits
        before = len(sets(events))  # (the quiet room's 0 may have gone already: the joint follows the signal)
        clapped = clapper.clap()
        first = wait_for(lambda: next((m for m in sets(events)[before:] if m["args"]["angles"] == [0.3]), None),
                         timeout=5, what="the map's joints/set of the clap")
        assert first["ok"] and first["args"]["names"] == ["HeadPitch"] and first["args"]["angles"] == [0.3]
        assert first["args"]["speed"] == 0.6
        figure("clap to joints/set carried out", (first["t"] - clapped) * 1000, "ms")
        assert moves.stats.get("skipped", 0) == 0  # (the onset after a silence is no sample going back in time)
        assert first["t"] - clapped < 0.5  # (a generous bound: measured ~25-40 ms here)
        wait_for(lambda: any(abs(v - head_moves(frames, 0)[0]) > 0.01 for v in head_moves(frames, clapped)),
                 what="the head moving")
        moved = next(m for m in frames.on("pepper/frame") if m["t"] >= clapped
                     and abs(m["v"][m["names"].index("HeadPitch")] - head_moves(frames, 0)[0]) > 0.01)
        figure("clap to the first frame with the head moved", (moved["t"] - clapped) * 1000, "ms")

        # during the nod, an operator's stop: the head stays where it stopped, the map's return is not sent
        stopped = client.send_command(watch, "pepper", "stop")
        assert stopped["held"] is True
        stop_t = time.time()
        wait_for(lambda: moves.chains["nod"].value == 0.0 and moves.stats["halted"] >= 1, timeout=5,
                 what="the clap's onset over, the map's return to 0 held back")
        held = moves.stats["halted"]
        assert held >= 1
        clapper.clap()  # another clap while halted: heard, mapped, not sent
        wait_for(lambda: ears.stats["onsets"] >= 2 and moves.stats["halted"] > held, timeout=5,
                 what="the second clap heard and held back", explain=lambda: f"{ears.stats} {moves.stats}")
        assert [m for m in sets(events) if m["t"] > stop_t] == []
        still = head_moves(frames, stop_t + 0.05)
        assert still and max(still) - min(still) < 0.005, still
        assert all(low <= v <= high for v in head_moves(frames, 0))
        assert moves.stats["commands_refused"] == 0

        # the operator resumes: the next clap nods again
        resumed = run_cli("resume", "moves", *net.cli_args())
        assert resumed.returncode == 0, resumed.stderr
        assert '"resumed": ["pepper"]' in resumed.stdout
        count = len(sets(events))  # (the map's output now, 0 in the quiet: sent at once, the joint follows again)
        clapper.clap()
        wait_for(lambda: [0.3] in [m["args"]["angles"] for m in sets(events)[count:]], timeout=5,
                 what="the nod after the resume")
    finally:
        clapper.close()
