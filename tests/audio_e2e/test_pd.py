"""The README's Pd example, run headless: patches/pd/examples/through-robot.pd on JACK
plays into the robot (naoqi-sim through the naoqi adapter) and records the robot's
microphones, with examples/sound-through-robot.toml's wiring (the jack adapter)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jack as jack_client
import numpy as np
import pytest
import soundfile

from sonibus.bus import decode, load_model, robot_info, send_command

from ..conftest import SONIBUS, free_port, require_tool, wait_for
from ..jack.conftest import peak_hz
from ..naoqi.conftest import toml_node

PATCH = Path(__file__).resolve().parents[2] / "patches" / "pd" / "examples" / "through-robot.pd"
RECORD_S = 12.0  # what the driver patch has Pd record before it quits
OUT = 48000

pytestmark = pytest.mark.external


def driver(tmp_path: Path, wav: Path) -> Path:
    """A second patch: record the microphones to ``wav`` for ``RECORD_S``, then quit Pd."""
    path = tmp_path / "driver.pd"
    path.write_text("\n".join([
        "#N canvas 0 50 400 300 12;",
        "#X obj 20 20 loadbang;",
        f"#X msg 20 50 \\; sonibus-record open {wav} \\, start;",
        f"#X obj 20 90 delay {RECORD_S * 1000:.0f};",
        "#X msg 20 120 \\; sonibus-record stop \\; pd quit;",
        "#X connect 0 0 1 0;", "#X connect 0 0 2 0;", "#X connect 2 0 3 0;", ""]))
    return path


def pd_ports(server: str) -> list[str]:
    probe = jack_client.Client("probe-pd", no_start_server=True, servername=server)
    try:
        return sorted(p.name for p in probe.get_ports("pure_data:*"))
    finally:
        probe.close()


@pytest.mark.realtime
def test_the_pd_example_plays_into_the_robot_and_records_its_microphones(jack, net, spawn, qi_client,
                                                                         tmp_path, figure):
    pd = require_tool("pd", "puredata")
    url = f"tcp://127.0.0.1:{free_port()}"
    robot_show, jack_show = tmp_path / "robot.toml", tmp_path / "jack.toml"
    robot_show.write_text(toml_node("fake", adapter="naoqi-sim", listen=url, rate_hz=50)
                          + toml_node("pepper", adapter="naoqi", url=url))
    client = net.bus("client")
    robot = spawn(SONIBUS, "run", str(robot_show), *net.cli_args(), collect=True, merge=True)
    wait_for(lambda: "audio" in (robot_info(client, "pepper", timeout=0.5) or {}), timeout=20,
             what="the robot's info with audio", explain=lambda: "\n".join(robot.lines))

    wav = tmp_path / "robot-mic.wav"
    patch = spawn(pd, "-nogui", "-stderr", "-jack", "-nojackconnect", "-inchannels", "1", "-outchannels", "2",
                  "-open", str(PATCH), "-open", str(driver(tmp_path, wav)), collect=True, merge=True)
    wait_for(lambda: len(pd_ports(jack)) == 3 or patch.popen.poll() is not None, timeout=10,
             what="Pd's JACK ports", explain=lambda: "\n".join(patch.lines))
    example = (Path(__file__).resolve().parents[2] / "examples" / "sound-through-robot.toml").read_text()
    jack_show.write_text("[nodes.jack]" + example.partition("[nodes.jack]")[2])  # the example's wiring
    tool = spawn(SONIBUS, "run", str(jack_show), *net.cli_args(), collect=True, merge=True)
    wait_for(lambda: any(line.startswith("sonibus: running") for line in tool.lines) or tool.popen.poll(),
             timeout=20, what="the jack adapter", explain=lambda: "\n".join(tool.lines))

    _frames, frames = client.subscribe("pepper/frame")
    head = load_model("pepper").joint_names.index("HeadYaw")
    latest: list[float] = [0.0]

    def head_at(angle: float) -> bool:
        for _key, payload in frames.drain(0):
            latest[0] = decode(payload)["v"][head]
        return abs(latest[0] - angle) < 0.05 or patch.popen.poll() is not None

    for move in range(4):  # the head turns from side to side while Pd records: a whine to hear
        angle = 1.0 if move % 2 == 0 else -1.0
        send_command(client, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [angle], "speed": 0.2})
        wait_for(lambda angle=angle: head_at(angle), timeout=10, what=f"HeadYaw at {angle}")
    wait_for(lambda: patch.popen.poll() is not None, timeout=RECORD_S + 10, what="Pd to quit once it has recorded")
    assert patch.popen.returncode == 0, "\n".join(patch.lines)
    assert not [line for line in patch.lines if "error" in line.lower() or "couldn't create" in line], patch.lines

    recorded, rate = soundfile.read(wav, dtype="float32")
    assert rate == OUT and recorded.ndim == 1  # JACK's rate, one channel (adc~ 1)
    assert float(np.sqrt(np.mean(recorded ** 2))) > 0.002, "the robot's whine was not recorded"
    figure("Pd's recording of the robot's microphones, RMS", float(np.sqrt(np.mean(recorded ** 2))), "of full scale")

    played_wav = tmp_path / "played.wav"
    qi_client(url).service("ALAudioDevice").dumpPlayed(str(played_wav))
    played: Any = soundfile.read(played_wav, dtype="int16")[0][:, 0]
    loud = played[np.abs(played) > 100]
    assert len(loud) > OUT, "Pd's sine was not played by the robot"
    assert peak_hz(played[-OUT * 2:].astype(np.float64), OUT) == pytest.approx(440.0, abs=2.0)
    assert np.abs(played).max() <= int(0.25 * 32767)  # the naoqi adapter's default ceiling
    for process in (tool, robot):
        assert process.stop()[0] == 130, process.lines
