"""``jack``: a robot's sound through JACK ports.

Input ports → ``<robot>/audio/speaker`` (Pd, SuperCollider or a DAW plays into
the robot); ``<robot>/audio/mic`` → output ports (the robot's microphones into
the sound tool). Both sides run at JACK's sample rate.

JACK's process callback runs on its real-time thread: it only copies. Input
frames go into a ``FrameRing`` that the ``publish`` worker cuts into
``chunk_ms`` chunks (int16, ``seq`` +1 each, ``t`` the wall clock of the first
frame); the output ports pull from a ``JitterBuffer`` that the ``receive``
worker fills from the bus. Frames the worker was too slow to take are counted
in ``input_lost`` and leave a gap in ``seq`` (whole chunks), so a player plays
silence for them rather than closing up the time.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import jack
import numpy as np

from sonibus.bus import codec, keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.audio import AudioChunk, received
from sonibus.bus.errors import ConfigError
from sonibus.bus.jitter import JitterBuffer
from sonibus.bus.node import AUDIO

from . import client as jack_client
from .config import JackConfig
from .ring import FrameRing

log = logging.getLogger(__name__)

RING_S = 1.0          # input frames the ring holds: how far behind the publish worker may fall
PAYLOAD_SLACK = 64    # bytes of a chunk's payload besides its PCM (t, seq, rate, channels, keys)
JITTER_STATS = ("underruns", "overruns", "gaps", "refused")
CLOSE_TIMEOUT_S = 2.0  # a JACK server that does not answer must not hold the node's stop (3 s at most)


class JackBridge(Adapter):
    """Robot audio as JACK ports: inputs to its speaker, its microphones to outputs."""

    Config = JackConfig
    counters = ("xruns", "chunks_sent", "chunks_silent", "chunks_received", "input_lost", *JITTER_STATS)

    def _start(self) -> None:
        cfg: JackConfig = self.config
        self._client: jack.Client | None = None
        self._ending = jack_client.ProcessEnd()
        self._failure: Exception | None = None  # what JACK's threads met, for the watch worker to fail with
        self._client = jack_client.open_client(cfg.client_name, cfg.server)
        self.client_name = self._client.name  # (JACK may have added -01: the ports are named after it)
        self.rate = self._client.samplerate
        self.chunk_frames = max(1, round(cfg.chunk_ms * self.rate / 1000))
        self._inputs = [self._client.inports.register(n) for n in cfg.input_names] if cfg.to_robot else []
        self._outputs = [self._client.outports.register(n) for n in cfg.output_names] if cfg.from_robot else []
        self._ring: FrameRing | None = None
        self._buffer: JitterBuffer | None = None
        if self._inputs:
            self._check_payload(len(self._inputs))
            self._ring = FrameRing(len(self._inputs), self.rate, int(RING_S * self.rate) + self.chunk_frames)
            self.stats.follow("input_lost", lambda: self._ring.lost if self._ring else 0)
            self._publisher = self.own(self.bus.stream_publisher(keys.audio(cfg.robot, "speaker"), AUDIO))
        if self._outputs:
            self._buffer = JitterBuffer(self.rate, len(self._outputs), target_ms=cfg.target_ms)
            for name in JITTER_STATS:
                self.stats.follow(name, lambda name=name: self._buffer.stats[name] if self._buffer else 0)
            subscriber, self._queue = self.bus.subscribe(keys.audio(cfg.robot, "mic"), maxlen=cfg.queue)
            self.own(subscriber)
            self.own(self._queue)
        self._client.set_process_callback(self._process)
        self._client.set_xrun_callback(lambda delay_us: self.count("xruns"))
        self._client.set_shutdown_callback(self._server_gone)
        self._client.activate()
        jack_client.connect(self._client, self._inputs, cfg.connect_inputs, "connect_inputs")
        jack_client.connect(self._client, self._outputs, cfg.connect_outputs, "connect_outputs")
        self.address = (f"JACK client '{self.client_name}' on server '{jack_client.server_name(cfg.server)}' at "
                        f"{self.rate} Hz: {', '.join(self.ports)}")
        log.info("%s: %s", self.name, self.address)
        if self._ring is not None:
            self.spawn(self._publish, "publish")
        if self._buffer is not None:
            self.spawn(self._receive, "receive")
        self.spawn(self._watch, "watch")

    @property
    def ports(self) -> list[str]:
        """The full names of this node's JACK ports (``sonibus:speaker_1``, ...)."""
        return [port.name for port in (*self._inputs, *self._outputs)]

    def metrics(self) -> dict[str, Any]:
        """JACK's sample rate and the client's name (read once: the client may be closing)."""
        return {"rate": self.rate, "jack_client": self.client_name} if hasattr(self, "rate") else {}

    def _stop(self) -> None:
        client, self._client = getattr(self, "_client", None), None
        # the ports go with the client; the callbacks stop before the workers are joined
        if client is not None and not jack_client.close_client(client, CLOSE_TIMEOUT_S, self._ending):
            log.warning("%s: JACK server '%s' did not answer within %g s: client '%s' and its ports stay "
                        "until it does (is jackd stopped or hung?)", self.name,
                        jack_client.server_name(self.config.server), CLOSE_TIMEOUT_S, self.client_name)

    def _check_payload(self, channels: int) -> None:
        size = self.chunk_frames * channels * 2 + PAYLOAD_SLACK
        if size > self.bus.limits.max_payload:
            most = (self.bus.limits.max_payload - PAYLOAD_SLACK) // (channels * 2) * 1000 // self.rate
            raise ConfigError(f"key 'chunk_ms': {self.config.chunk_ms:g} ms of {channels} channels at "
                              f"{self.rate} Hz is {size} bytes, over the bus's limit of "
                              f"{self.bus.limits.max_payload} — at most {most} ms")

    # -- JACK's threads: copy, count, never the bus --------------------------------------

    def _process(self, frames: int) -> None:
        self._ending.check()  # (first, out of the try: its CallbackExit is a stop, not a failure)
        try:
            if self._ring is not None:
                self._ring.write([port.get_array() for port in self._inputs], time.time())
            if self._buffer is not None:
                block = self._buffer.pull(frames)
                for channel, port in enumerate(self._outputs):
                    np.multiply(block[:, channel], 1 / 32768, out=port.get_array(), casting="same_kind")
        except Exception as exc:  # JACK would stop calling: the watch worker fails the node with it
            self._failure = exc
            raise jack.CallbackExit from None

    def _server_gone(self, status: jack.Status, reason: str) -> None:
        self._failure = jack_client.ServerGone(f"JACK server '{jack_client.server_name(self.config.server)}' "
                                               f"went away: {reason}")

    # -- workers --------------------------------------------------------------------------

    def _watch(self) -> None:
        """Turns what JACK's threads met into the node's failure (``Adapter.fail``)."""
        while not self.stopping.wait(0.1):
            if self._failure is not None:
                raise self._failure

    def _publish(self) -> None:
        ring, seq, lost = self._ring, 0, 0
        assert ring is not None
        period = self.chunk_frames / self.rate
        while not self.stopping.wait(period / 2):
            while (taken := ring.read(self.chunk_frames)) is not None:
                if ring.lost != lost:  # whole chunks skipped: the seq says so
                    seq += (ring.lost - lost) // self.chunk_frames
                    lost = ring.lost
                    self.warn("input_lost", "input frames lost: the publish worker fell behind JACK")
                t, frames = taken
                if not frames.any() and not self.config.send_silence:
                    # a quiet or closed sound tool: nothing goes out (no seq used, so no gap), the robot's
                    # jitter buffer runs dry, fades out and its speaker stops calling the robot
                    self.count("chunks_silent")
                    continue
                chunk = AudioChunk.from_samples(t, seq, self.rate, frames)
                self._publisher.put(codec.encode(chunk.message()))
                self.count("chunks_sent")
                seq += 1

    def _receive(self) -> None:
        buffer, gate = self._buffer, messages.Gate(self.bus.limits)
        assert buffer is not None
        while not self.stopping.is_set():
            for key, payload in self._queue.drain(timeout=0.2):
                chunk = received(gate, key, payload, self.count, self.warn)
                if chunk is None:
                    continue
                buffer.push(chunk)
                self.count("chunks_received")
                self.record_latency(time.time() - chunk.t)
