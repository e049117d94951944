"""Sound through the robot, every part real: a sine a JACK client plays into the
``jack`` adapter reaches naoqi-sim's speaker through the ``naoqi`` adapter; the
whine of naoqi-sim's microphones, published by the ``naoqi`` adapter, comes out of
the ``jack`` adapter's output port and follows a commanded joint move; stopping
any node leaves no JACK ports and no threads behind."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest
import soundfile

from sonibus.adapters.jack import JackBridge, JackConfig
from sonibus.bus import health, robot_info, send_command

from ..conftest import SONIBUS, free_port, wait_for
from ..jack.conftest import Peer, peak_hz
from ..jackd import RATE
from ..naoqi.conftest import toml_node

HZ = 1000.0          # the tester's sine (tests/jack/conftest.py Peer)
AMPLITUDE = 0.5      # its level, of full scale
CEILING = 0.25       # the naoqi adapter's default volume ceiling
OUT = 48000          # the robot's output rate
QUIET = 100          # |sample| at or below this is silence (the sine peaks at 0.5 × 0.25 × 32768)
SECONDS = 10.0
SETTLE = OUT // 2  # the first 0.5 s of sound is left out


def bridge(net: Any, **options: Any) -> JackBridge:
    return net.start(JackBridge(JackConfig(robot="pepper", **options), name="jack"))


def heard(peer: Peer) -> int:
    """Frames the tester's input port has heard so far."""
    return sum(len(block) for block in list(peer.heard))


def node_threads(name: str) -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith(f"{name}:")]


def quiet_runs(signal: np.ndarray, at_least: int) -> list[tuple[int, int]]:
    """(start, length) of every run of ``at_least`` samples or more at or below ``QUIET``."""
    quiet = np.concatenate(([0], (np.abs(signal) <= QUIET).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(quiet))
    return [(int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= at_least]


def counters(bus: Any, node: str) -> dict[str, int]:
    """Node ``node``'s counters, as it serves its stats on the bus."""
    for (_host, name), stats in health.latest(bus).items():
        if name == node and isinstance(stats, dict):
            return stats["counters"]
    pytest.fail(f"node {node} serves no stats")


def info_of(bus: Any) -> dict[str, Any]:
    return robot_info(bus, "pepper", timeout=0.5) or {}


# Fixture order: peer (its JACK server) before rig and net, so that the nodes stop first, then the
# fake robot, then the server.

@pytest.mark.realtime
def test_a_sine_into_the_jack_adapter_is_played_by_the_robot(peer, net, spawn, qi_client, tmp_path, figure):
    # Each side in a process of its own, as on two machines: the robot (naoqi-sim and the naoqi
    # adapter) and the sound tool's jack adapter. In this process they would share one
    # interpreter with the test's JACK client, whose late cycles slow the dummy driver's clock.
    # A 2 s jitter buffer: the dummy driver's clock still lags the wall clock on a busy machine
    # while the robot's speaker drains at wall-clock pace; bench/audio.py measures the default.
    url = f"tcp://127.0.0.1:{free_port()}"
    robot_show, jack_show = tmp_path / "robot.toml", tmp_path / "jack.toml"
    robot_show.write_text(toml_node("fake", adapter="naoqi-sim", listen=url, rate_hz=50, played_max_s=30.0)
                          + toml_node("pepper", adapter="naoqi", url=url, speaker_latency_ms=2000))
    jack_show.write_text(toml_node("jack", adapter="jack", robot="pepper", from_robot=False, inputs=1)
                         + 'connect_inputs = ["tester:sine"]\n')
    client = net.bus("client")
    robot = spawn(SONIBUS, "run", str(robot_show), *net.cli_args(), collect=True, merge=True)
    wait_for(lambda: "audio" in info_of(client), timeout=20, what="the robot's info with audio",
             explain=lambda: "\n".join(robot.lines))
    tool = spawn(SONIBUS, "run", str(jack_show), *net.cli_args(), collect=True, merge=True)
    wait_for(lambda: peer.ports("sonibus:") or tool.popen.poll() is not None, timeout=20,
             what="the jack adapter's ports", explain=lambda: "\n".join(tool.lines))
    started, played = time.monotonic(), peer.played
    device = qi_client(url).service("ALAudioDevice")
    wav = tmp_path / "played.wav"
    checked = [0.0]

    def sounding() -> list[np.ndarray]:
        if time.monotonic() < checked[0] + 1.0:  # (a dump is a few MB: once a second)
            return []
        checked[0] = time.monotonic()
        device.dumpPlayed(str(wav))
        played = soundfile.read(wav, dtype="int16")[0][:, 0]
        loud = np.flatnonzero(np.abs(played) > QUIET)
        first = loud[0] + SETTLE if loud.size else 0  # (JACK may play a period or two of zeros as it connects)
        if loud.size and loud[-1] - first >= SECONDS * OUT:
            return [played[first:first + round(SECONDS * OUT)].astype(np.int32)]
        return []

    [signal] = wait_for(sounding, timeout=SECONDS + 20, what=f"{SECONDS:g} s of the sine played by the robot",
                        explain=lambda: "\n".join(robot.lines + tool.lines))
    figure("dummy JACK clock / wall clock", (peer.played - played) / RATE / (time.monotonic() - started), "")
    speaker, bridge_counts = counters(client, "pepper"), counters(client, "jack")
    for process in (tool, robot):
        code, _, _ = process.stop()
        # (an error is logged as "ERROR:" or "error:"; the stop line counts "errors 0")
        errors = [line for line in process.lines if "ERROR" in line or "error:" in line]
        assert code == 130 and not errors, process.lines  # Ctrl-C
    assert peak_hz(signal / 32768, OUT) == pytest.approx(HZ, abs=2.0)
    assert quiet_runs(signal, at_least=24) == [], (speaker, bridge_counts)  # 0.5 ms quiet inside: a gap
    assert np.abs(signal).max() <= int(CEILING * 32767)
    assert np.abs(signal).max() > 0.8 * AMPLITUDE * CEILING * 32767  # the level played, under the ceiling
    assert speaker["speaker_gaps"] == 0 and bridge_counts["input_lost"] == 0
    assert speaker["speaker_errors"] == 0  # naoqi-sim refuses a call over 16384 frames (tests/naoqi/test_audio)
    figure("speaker calls, mean frames", speaker["speaker_frames"] / max(1, speaker["speaker_calls"]), "")


@pytest.mark.realtime
def test_the_robots_whine_comes_out_of_the_jack_adapter_and_follows_a_joint_move(peer, rig, net, figure):
    r = rig()
    fake = r.fake
    wait_for(lambda: r.adapter.audio_present, what="the adapter to find ALAudioDevice")
    node = bridge(net, to_robot=False, outputs=1, connect_outputs=("tester:ear",))
    wait_for(lambda: node.stats["chunks_received"] >= 5, timeout=10, what="mic chunks at the jack adapter",
             explain=lambda: f"jack {dict(node.stats)}; naoqi {dict(r.adapter.stats)}")
    rest = heard(peer)
    wait_for(lambda: heard(peer) >= rest + RATE, what="1 s heard at rest")
    command = heard(peer)
    send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [-1.5], "speed": 0.1})
    wait_for(lambda: fake.engine.body.moving(["HeadYaw"]), what="the head to move")
    wait_for(lambda: not fake.engine.body.moving(["HeadYaw"]), timeout=10, what="the head to stop")
    stopped = heard(peer)
    wait_for(lambda: heard(peer) >= stopped + 2 * RATE, timeout=10, what="2 s heard after the move")
    recording = peer.recording().astype(np.float64)
    lag = round(0.8 * RATE)  # the robot's 170 ms buffers, the jitter buffer, JACK's periods: well within

    def level(first: int, last: int) -> float:
        assert last - first >= RATE // 4, (first, last)
        return float(np.sqrt(np.mean(recording[first:last] ** 2)))

    before, during = level(rest, command), level(command + lag, stopped)
    after = level(stopped + lag + RATE // 2, stopped + 2 * RATE)
    assert during > 10 * max(before, after, 1e-4), (before, during, after)
    assert peak_hz(recording[command + lag:stopped], RATE) > 150  # a buzz, not a hum
    figure("whine RMS while HeadYaw moves at 0.1 × max speed", during, "of full scale")


@pytest.mark.parametrize("first", ["robot owner", "bridge"])
def test_stopping_any_node_leaves_no_ports_and_no_threads(peer, rig, net, first):
    r = rig()
    device = r.fake.services["ALAudioDevice"]
    wait_for(lambda: r.adapter.audio_present, what="the adapter to find ALAudioDevice")
    node = bridge(net, inputs=1, outputs=1, connect_inputs=("tester:sine",), connect_outputs=("tester:ear",))
    wait_for(lambda: node.stats["chunks_received"] >= 5 and len(device.played()) > OUT // 10, timeout=15,
             what="audio both ways", explain=lambda: f"jack {dict(node.stats)}; naoqi {dict(r.adapter.stats)}")
    assert peer.ports("sonibus:") == ["sonibus:mic_1", "sonibus:speaker_1"]

    if first == "robot owner":  # the bridge goes on, its ports stay
        r.adapter.stop()
        assert node_threads(r.adapter.name) == []
        assert node.state == "running" and peer.ports("sonibus:") == ["sonibus:mic_1", "sonibus:speaker_1"]
        sent = node.stats["chunks_sent"]
        wait_for(lambda: node.stats["chunks_sent"] >= sent + 20, what="the bridge to go on publishing")
    node.stop()
    assert peer.ports("sonibus:") == []
    assert node_threads(node.name) == []
    if first == "bridge":  # the robot's owner goes on; nobody listens to the microphones any more
        assert r.adapter.state == "running"
        wait_for(lambda: not r.adapter.microphones.subscribed and not device.listeners, timeout=10,
                 what="the robot's owner to unsubscribe ALAudioDevice")
        r.adapter.stop()
        assert node_threads(r.adapter.name) == []
    r.fake.stop()
    assert [t.name for t in threading.enumerate() if t.name.startswith("fake-naoqi")] == []
