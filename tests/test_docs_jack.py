"""The docs' Pd-through-JACK commands (issue 29, item 14): `pd -jack` connects Pd to the
sound card by itself, so `adc~ 1` mixed the laptop's microphone into the robot's; the
docs now start Pd with `-nojackconnect` (sonibus's jack node makes the connections
its file names), with as many channels as the example they run beside it has ports
(docs/jack.md said `-inchannels 2` beside a file of one microphone port)."""

from __future__ import annotations

import threading
import tomllib
from pathlib import Path

import jack as jack_client
import numpy as np

from .conftest import require_tool, wait_for
from .jackd import jack  # noqa: F401  (the fixture: a private JACK server, dummy driver)
from .test_docs_commands import DOCS, ROOT, examples


def pd_commands() -> list[tuple[str, list[str], Path]]:
    """Each doc's `pd -jack ...` command, with the example file the doc runs beside it."""
    found = []
    for path in DOCS:
        commands = examples(path)
        for i, example in enumerate(commands):
            if example.words[0] == "pd" and "-jack" in example.words:
                beside = next(e for e in commands[i:] if e.words[:2] == ["sonibus", "run"])
                found.append((str(example), example.words, ROOT / beside.words[2]))
    return found


def _flag(words: list[str], name: str) -> int:
    return int(words[words.index(name) + 1])


def test_the_docs_start_pd_without_its_own_connections_and_with_the_examples_channels():
    commands = pd_commands()
    assert {where.split(":")[0] for where, _, _ in commands} >= {"README.md", "docs/jack.md"}
    for where, words, example in commands:
        assert "-nojackconnect" in words, f"{where}: Pd would connect the sound card's inputs to adc~ by itself"
        node = next(n for n in tomllib.loads(example.read_text())["nodes"].values() if n["adapter"] == "jack")
        assert _flag(words, "-inchannels") == node["outputs"], f"{where}: {example.name} has {node['outputs']} mic"
        assert _flag(words, "-outchannels") == node["inputs"], f"{where}: {example.name} has {node['inputs']} inputs"


def connections(server: str) -> dict[str, list[str]]:
    probe = jack_client.Client("probe-docs", no_start_server=True, servername=server)
    try:
        return {p.name: sorted(q.name for q in probe.get_all_connections(p)) for p in probe.get_ports("pure_data:*")}
    finally:
        probe.close()


def hearing(server: str, port: str) -> tuple[jack_client.Client, threading.Event]:
    """A JACK client of the test's that listens to ``port``: its event is set once sound comes."""
    client = jack_client.Client("listener", no_start_server=True, servername=server)
    heard = threading.Event()
    listening = client.inports.register("in")

    @client.set_process_callback
    def process(frames: int) -> None:
        if np.any(listening.get_array()):
            heard.set()

    client.activate()
    client.connect(port, listening)
    return client, heard


def test_pd_started_as_the_readme_says_connects_nothing_of_the_sound_card(jack, spawn):  # noqa: F811
    """On a JACK server with a (dummy) sound card: the README's command leaves Pd's ports
    unconnected (checked once its tone sounds: Pd connects, if it does, before it plays);
    the same without `-nojackconnect` (what the docs said) wires system:capture_1 into
    Pd's adc~ 1 and its dac~ into the sound card."""
    pd = require_tool("pd", "puredata-core")
    words = next(w for where, w, _ in pd_commands() if where.startswith("README.md"))
    headless = ["-nogui", "-stderr"]  # (the README's Pd has a window)
    process = spawn(pd, *headless, *words[1:], cwd=ROOT, collect=True, merge=True)
    wait_for(lambda: len(connections(jack)) == 3, timeout=20, what="Pd's three JACK ports",
             explain=lambda: "\n".join(process.lines))
    listener, heard = hearing(jack, "pure_data:output_1")
    try:
        wait_for(heard.is_set, timeout=20, what="Pd's tone (its DSP running)")
        assert connections(jack) == {"pure_data:input_1": [], "pure_data:output_1": ["listener:in"],
                                     "pure_data:output_2": []}
    finally:
        listener.close()
    process.kill()
    wait_for(lambda: not connections(jack), what="Pd gone from JACK")

    process = spawn(pd, *headless, *(w for w in words[1:] if w != "-nojackconnect"), cwd=ROOT, collect=True)
    wait_for(lambda: connections(jack).get("pure_data:input_1") == ["system:capture_1"], timeout=20,
             what="Pd's own wiring of the sound card", explain=lambda: f"{connections(jack)}")
    assert connections(jack)["pure_data:output_1"] == ["system:playback_1"]
