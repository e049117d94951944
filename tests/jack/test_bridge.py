"""The jack adapter on a real JACK server (dummy driver): a sine into its input
port reaches <robot>/audio/speaker, chunks on <robot>/audio/mic come out of its
output port, a missing server is one line, and stop leaves nothing behind."""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
import uuid

import jack
import numpy as np
import pytest

from sonibus.adapters.jack import JackBridge, JackConfig
from sonibus.adapters.jack import client as jack_client
from sonibus.bus import codec, keys
from sonibus.bus.audio import AudioChunk
from sonibus.bus.errors import ConfigError
from sonibus.bus.messages import Gate
from sonibus.bus.node import AUDIO

from ..conftest import run_cli, wait_for
from ..jackd import RATE
from .conftest import peak_hz


def bridge(net, name: str = "jack", **options) -> JackBridge:
    return net.start(JackBridge(JackConfig(robot="pepper", **options), name=name))


@pytest.mark.realtime
def test_a_sine_into_an_input_port_arrives_on_the_speaker_key(net, peer, figure):
    listener = net.bus("listener")
    subscriber, queue = listener.subscribe(keys.audio("pepper", "speaker"), maxlen=4096)
    node = bridge(net, from_robot=False, inputs=1, connect_inputs=("tester:sine",))
    gate, chunks, delays = Gate(), [], []

    def received(wanted: int) -> bool:
        while (item := queue.get(timeout=0)) is not None:
            chunks.append(AudioChunk.of(gate.check(keys.Key.parse(item[0]), item[1])))
            delays.append(time.time() - chunks[-1].t)
        return len(chunks) >= wanted

    wait_for(lambda: received(80), timeout=20, what="80 chunks on pepper/audio/speaker",
             explain=lambda: f"{len(chunks)} chunks; node stats {dict(node.stats)}")
    subscriber.undeclare()
    assert {(c.rate, c.channels, c.frames) for c in chunks} == {(RATE, 1, RATE // 100)}  # chunk_ms 10
    seqs = [c.seq for c in chunks]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "a gap or a reordering"
    steps = np.diff([c.t for c in chunks])
    signal = np.concatenate([c.samples()[:, 0] for c in chunks[-50:]]) / 32767  # (the first may precede the link)
    assert peak_hz(signal, RATE) == pytest.approx(1000.0, abs=RATE / len(signal))
    assert 0.45 < np.abs(signal).max() < 0.55  # the amplitude played, as int16
    assert node.stats["chunks_sent"] >= len(chunks)
    figure("chunk t step spread (max - min)", float(steps.max() - steps.min()) * 1000, "ms")
    figure("latency: a chunk's first frame to the subscriber, p50", float(np.median(delays)) * 1000, "ms")


@pytest.mark.parametrize("send_silence", [False, True])
def test_digital_silence_is_not_sent_unless_asked(net, jack, send_silence):
    """An input nothing plays into (a closed Pd) sent zeros 100 times a second for ever, and a
    robot's speaker called the robot 50 times a second for them."""
    listener = net.bus("listener")
    subscriber, queue = listener.subscribe(keys.audio("pepper", "speaker"), maxlen=4096)
    node = bridge(net, from_robot=False, inputs=1, send_silence=send_silence)
    counted = "chunks_sent" if send_silence else "chunks_silent"
    wait_for(lambda: node.stats[counted] >= 50, timeout=20, what=f"50 {counted}")
    subscriber.undeclare()
    arrived = len(queue.drain(0))
    if send_silence:
        assert arrived and node.stats["chunks_silent"] == 0
    else:
        assert arrived == 0 and node.stats["chunks_sent"] == 0, dict(node.stats)


@pytest.mark.realtime
def test_chunks_on_the_mic_key_come_out_of_an_output_port(net, peer, figure):
    node = bridge(net, to_robot=False, outputs=2, connect_outputs=("tester:ear",), target_ms=60)
    robot = net.bus("robot")
    publisher = robot.stream_publisher(keys.audio("pepper", "mic"), AUDIO)
    rate, hz, frames = 16000, 440.0, 320  # a robot's microphones: 16 kHz mono, 20 ms chunks
    start, sent = time.monotonic(), 0

    def play_and_listen() -> bool:
        """Publish the chunks due by now (paced by the clock); enough once the ear heard 0.5 s of sound."""
        nonlocal sent
        while start + sent * frames / rate <= time.monotonic():
            n = np.arange(sent * frames, (sent + 1) * frames)
            chunk = AudioChunk.from_samples(time.time(), sent, rate, 0.5 * np.sin(2 * np.pi * hz * n / rate))
            publisher.put(codec.encode(chunk.message()))
            sent += 1
        return int((np.abs(peer.recording()) > 0.1).sum()) >= RATE // 2

    wait_for(play_and_listen, timeout=20, what="0.5 s of sound out of jack:mic_1",
             explain=lambda: f"{sent} chunks sent; node stats {dict(node.stats)}")
    publisher.undeclare()
    heard = peer.recording()
    loud = np.flatnonzero(np.abs(heard) > 0.1)
    signal = heard[loud[0]:loud[-1] + 1]
    assert peak_hz(signal, RATE) == pytest.approx(hz, abs=2 * RATE / len(signal))  # resampled 16 → 48 kHz
    assert np.abs(signal).max() < 0.55
    assert node.stats["chunks_received"] > 0 and node.stats["bad"] == 0
    figure("underruns while playing", node.stats["underruns"])
    figure("first mic chunk published → first sound out of the port (target_ms 60)",
           (peer.first_sound - start) * 1000, "ms")


def test_port_names_and_the_client_name_are_configurable(net, peer):
    bridge(net, client_name="robotsound", inputs=("left", "right"), outputs=("front",))
    assert peer.ports("robotsound:", is_input=True) == ["robotsound:left", "robotsound:right"]
    assert peer.ports("robotsound:", is_output=True) == ["robotsound:front"]
    bridge(net, name="jack2", client_name="counted", inputs=3, outputs=1)
    assert peer.ports("counted:", is_input=True) == ["counted:speaker_1", "counted:speaker_2", "counted:speaker_3"]
    assert peer.ports("counted:", is_output=True) == ["counted:mic_1"]


def test_stop_leaves_no_ports_and_no_threads(net, peer):
    bus = net.bus("jack")
    threads_before = _os_threads()
    node = JackBridge(JackConfig(robot="pepper", client_name="bridge"), name="jack")
    node.start(bus)
    assert len(peer.ports("bridge:")) == 4
    wait_for(lambda: _os_threads() > threads_before, what="JACK's threads of the client")
    node.stop()
    assert peer.ports("bridge:") == []
    assert not [t.name for t in threading.enumerate() if t.name.startswith("jack:")]
    wait_for(lambda: _os_threads() <= threads_before, what="JACK's threads gone",
             explain=lambda: f"{_os_threads()} threads, {threads_before} before")


def test_stop_ends_the_process_thread_before_jack_deactivates_the_client(net, peer, monkeypatch):
    """jack2 cancels a client's process thread when deactivating it: one cancelled while in Python
    holds the GIL for ever (a suite's worker hung so); the thread must be gone by then."""
    process, deactivate = JackBridge._process, jack.Client.deactivate
    threads: list[int] = []
    alive_at_deactivate: list[bool] = []

    def traced(self, frames):
        if not threads:
            threads.append(threading.get_native_id())
        return process(self, frames)

    def traced_deactivate(self, *args, **kwargs):
        alive_at_deactivate.extend(os.path.exists(f"/proc/self/task/{tid}") for tid in threads)
        return deactivate(self, *args, **kwargs)

    monkeypatch.setattr(JackBridge, "_process", traced)
    monkeypatch.setattr(jack.Client, "deactivate", traced_deactivate)
    node = JackBridge(JackConfig(robot="pepper", client_name="ending"), name="jack")
    node.start(net.bus("jack"))
    wait_for(lambda: threads, what="the bridge's process callback")
    node.stop()
    assert alive_at_deactivate == [False]
    assert peer.ports("ending:") == []


def test_a_port_to_connect_that_is_not_there_is_an_error_naming_the_key_and_the_ports(net, peer):
    with pytest.raises(ConfigError) as error:
        bridge(net, client_name="bridge", connect_inputs=("pd:output_1",))
    assert "key 'connect_inputs'" in str(error.value) and "'tester:sine'" in str(error.value)
    assert peer.ports("bridge:") == []  # the failed start gave its client back


def test_a_missing_server_is_one_line_and_a_non_zero_exit(net, tmp_path):
    server = f"nosuch-{uuid.uuid4().hex[:8]}"
    show = tmp_path / "show.toml"
    show.write_text(f'[nodes.jack]\nadapter = "jack"\nrobot = "pepper"\nserver = "{server}"\n')
    result = run_cli("run", str(show), *net.cli_args())
    assert result.returncode != 0
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sonibus: error: "), result.stderr
    assert f"no JACK server '{server}' running" in lines[0] and f"jackd -n {server} -d dummy" in lines[0]
    assert "line 4: key 'server'" in lines[0]  # placed in the file


def _os_threads() -> int:
    """This process's threads named like the process: JACK's and Python's (Zenoh's runtimes name theirs)."""
    def name(task: str) -> str:
        try:
            with open(f"/proc/self/task/{task}/comm") as comm:
                return comm.read()
        except OSError:  # ended meanwhile
            return ""
    own = name(str(os.getpid()))
    return sum(name(task) == own for task in os.listdir("/proc/self/task"))


def test_a_server_that_goes_away_fails_the_node_in_one_line(net, jack_server, caplog):
    name, server = jack_server
    node = bridge(net, client_name="bridge")
    server.stop(timeout=5)
    wait_for(lambda: node.failure, what="the node to fail")
    assert node.state == "failed" and f"ServerGone: JACK server '{name}' went away" in node.failure
    assert len(node.failure.splitlines()) == 1
    said = [r for r in caplog.records if r.levelno >= logging.WARNING and "went away" in r.getMessage()]
    assert said and all(r.exc_info is None for r in said)  # no traceback: a failure foreseen
    node.stop()  # (closing a client whose server is gone returns)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("jack:")]


def test_stop_is_bounded_while_the_jack_server_does_not_answer(net, jack_server, caplog):
    name, server = jack_server
    node = bridge(net, client_name="bridge")
    os.kill(server.popen.pid, signal.SIGSTOP)  # jackd hangs: libjack waits for it without a bound
    try:
        stopping = threading.Thread(target=node.stop, daemon=True)
        stopping.start()
        stopping.join(10.0)  # (the node's own bound is 2 s; a stop that hangs fails here instead of hanging)
        assert not stopping.is_alive(), "stop hangs on a JACK server that does not answer"
    finally:
        os.kill(server.popen.pid, signal.SIGCONT)
    assert node.state == "stopped"
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any(f"JACK server '{name}' did not answer" in line and "'bridge'" in line for line in said), said
    wait_for(lambda: not [t for t in threading.enumerate() if t.name.startswith("jack-close-")],
             what="the client closed once the server answers again")
    assert not [t.name for t in threading.enumerate() if t.name.startswith("jack:")]


def test_a_jack_server_that_does_not_answer_at_start_is_one_line_not_a_hang(net, jack_server, monkeypatch):
    name, server = jack_server
    monkeypatch.setattr(jack_client, "OPEN_TIMEOUT_S", 1.0)
    os.kill(server.popen.pid, signal.SIGSTOP)  # jackd stopped (Ctrl-Z in its terminal)
    try:
        errors: list[str] = []
        starting = threading.Thread(target=lambda: errors.append(_start_error(net)), daemon=True)
        starting.start()
        starting.join(10.0)
        assert not starting.is_alive(), "start hangs on a JACK server that does not answer"
    finally:
        os.kill(server.popen.pid, signal.SIGCONT)
    assert len(errors) == 1 and f"JACK server '{name}' does not answer" in errors[0], errors
    assert len(errors[0].splitlines()) == 1
    wait_for(lambda: not [t for t in threading.enumerate() if t.name.startswith("jack-open-")],
             what="the late open to end once the server answers again")
    probe = jack.Client("probe", no_start_server=True, servername=name)
    try:
        assert not [p.name for p in probe.get_ports() if p.name.startswith("bridge:")], "a late client stayed"
    finally:
        probe.close()


def _start_error(net) -> str:
    with pytest.raises(ConfigError) as error:
        bridge(net, client_name="bridge")
    return str(error.value)
