"""Options of the ``naoqi`` adapter: where the robot is, how to read it.

>>> NaoqiConfig(url="192.168.1.20").endpoint
'tcp://192.168.1.20:9559'
>>> NaoqiConfig(url="tcps://10.0.0.4", password="nao").endpoint
'tcps://10.0.0.4:9503'
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from sonibus.bus.options import bad
from sonibus.bus.robot import models

Source = Literal["auto", "almemory", "motion"]
Quantity = Literal["cmd", "cur", "temp"]
MicChannels = Literal["all", "left", "right", "front", "rear"]

MIC_RATES = (16000, 48000)  # what ALAudioDevice.setClientPreferences accepts

DEFAULT_PORTS = {"tcp": 9559, "tcps": 9503}
_URL = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:.]+\]|[^:/\s]+)(?::(?P<port>\d+))?/?$")


@dataclass(frozen=True)
class NaoqiConfig:
    """Options of the ``naoqi`` adapter."""

    robot: str = "pepper"               # bus name of the robot
    url: str = "tcp://127.0.0.1:9559"   # NAOqi 2.5 / NAO: tcp://host:9559; NAOqi 2.9: tcps://host:9503
    user: str = "nao"                   # tcps:// only (NAOqi 2.9 authentication)
    password: str = ""                  # tcps:// only; required there
    model: str = ""                     # pepper | nao, used until the robot answers; default: robot name
    rate_hz: float = 50.0               # frames per second asked of the robot
    source: Source = "auto"             # auto: motion for NAO V6 / NAOqi >= 2.8, else almemory
    extra: tuple[Quantity, ...] = ()    # more fields per joint sample: cmd, cur, temp
    pause_awareness: bool = False       # pause basic awareness while running, restore it on stop
    connect_timeout_s: float = 5.0      # a connect, or any call, that takes longer means the link is down
    answer_timeout_s: float = 1.0       # no frame read for this long: "not answering", commands refused until one is
    retry_max_s: float = 10.0           # reconnect backoff grows from 0.25 s up to this
    status_every_s: float = 5.0         # a ``status`` event (achieved rate, read latency) this often
    audio: bool = True                  # <robot>/audio/mic and /speaker, if the robot has ALAudioDevice
    mic_rate: int = 16000               # 16000 or 48000 Hz, as ALAudioDevice delivers them
    mic_channels: MicChannels = "all"   # all four microphones, or one of them
    speaker_latency_ms: float = 100.0   # the speaker's jitter buffer: playback starts once this much is buffered
    volume_ceiling: float = 0.25        # |sample| never above this fraction of full scale (visitors stand close)

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz <= 1000:
            raise bad("rate_hz", f"{self.rate_hz:g} must be in (0, 1000]")
        if self.model_name not in models():
            raise bad("model", f"'{self.model_name}' is unknown — known models: {', '.join(models())}")
        scheme = self._parts()[0]
        if scheme not in DEFAULT_PORTS:
            raise bad("url", f"'{self.url}' has scheme '{scheme}': use tcp://host:9559 or tcps://host:9503")
        if scheme == "tcps" and not self.password:
            raise bad("password", f"{self.url} (NAOqi 2.9) needs a user and password, "
                      f"e.g. user = \"nao\", password = \"...\"")
        if scheme == "tcp" and self.password:
            raise bad("password", f"a password needs tcps://host:9503 (NAOqi 2.9), not {self.url}")
        if len(set(self.extra)) != len(self.extra):
            raise bad("extra", f"{list(self.extra)} names a quantity twice")
        for key in ("connect_timeout_s", "answer_timeout_s", "retry_max_s", "status_every_s"):
            if not getattr(self, key) > 0:
                raise bad(key, f"{getattr(self, key):g} must be more than 0")
        if self.mic_rate not in MIC_RATES:
            raise bad("mic_rate", f"{self.mic_rate} Hz: ALAudioDevice delivers 16000 or 48000")
        if not 10 <= self.speaker_latency_ms <= 2000:
            raise bad("speaker_latency_ms", f"{self.speaker_latency_ms:g} must be in [10, 2000]")
        if not 0 < self.volume_ceiling <= 1:
            raise bad("volume_ceiling", f"{self.volume_ceiling:g} must be in (0, 1] (a fraction of full scale)")

    @property
    def model_name(self) -> str:
        return self.model or self.robot.rstrip("0123456789")

    @property
    def endpoint(self) -> str:
        """``url`` with its scheme and port spelled out."""
        scheme, host, port = self._parts()
        return f"{scheme}://{host}:{port or DEFAULT_PORTS[scheme]}"

    def _parts(self) -> tuple[str, str, str]:
        match = _URL.match(self.url.strip())
        if match is None:
            raise bad("url", f"'{self.url}' is not a URL like tcp://192.168.1.20:9559")
        return match["scheme"] or "tcp", match["host"], match["port"] or ""
