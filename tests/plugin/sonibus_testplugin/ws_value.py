"""ws-value: the latest value of one robot joint, over HTTP and WebSocket."""

from dataclasses import dataclass

from aiohttp import web

from sonibus.bus import Adapter, SampleQueue
from sonibus.bus.options import bad
from sonibus.bus.streams import Streams
from sonibus.bus.web import WebServer


@dataclass(frozen=True)
class ValueServerConfig:
    robot: str = "pepper"
    joint: str = "HeadYaw"
    host: str = "127.0.0.1"
    port: int = 8080                          # 0: any free port

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise bad("port", f"{self.port} must be in [0, 65535]")


class ValueServer(Adapter):
    """Serves the latest value of one joint: GET /value, and each new one on /ws."""

    Config = ValueServerConfig

    def _start(self) -> None:
        self.web = WebServer(self, self.config.host, self.config.port)
        self.web.app.router.add_get("/value", self.value)
        self.web.app.router.add_get("/ws", self.web.websocket)  # every broadcast, to every client
        self.queue = self.own(SampleQueue(64))  # its drops count as the node's `dropped`
        self.streams = self.own(Streams(self.bus, [f"{self.config.robot}/joints/{self.config.joint}"],
                                        self.queue))  # the joint, out of the robot's frames
        self.web.start()                      # listening on self.web.port; stopped by stop()
        self.spawn(self.forward, "forward")   # joined by stop()

    async def value(self, request: web.Request) -> web.Response:
        return web.json_response(self.web.latest)

    def forward(self) -> None:
        while not self.stopping.is_set():
            item = self.queue.get(timeout=0.2)
            message = self.streams.take(*item, self.count, self.warn) if item else None  # checked, counted
            for sample in message.joints if message else ():
                self.web.broadcast({"robot": self.config.robot, "joint": self.config.joint,
                                    "t": sample.t, "v": sample.values[0]})
                self.count("sent")
