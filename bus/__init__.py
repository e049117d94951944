"""sonibus core: the bus, its keys and payloads, adapters and their lifecycle.

    from contextlib import closing
    from sonibus.bus import Bus, BusConfig, open_session, send_command

    with closing(open_session(BusConfig())) as session:  # join the bus (and close it at the end)
        bus = Bus(session)
        send_command(bus, "pepper", "say", {"text": "hello"})
        subscriber, queue = bus.subscribe("pepper/joints/*")
        key, payload = queue.get(timeout=1.0)           # ('pepper/joints/HeadYaw', b'...')
        decode(payload)                                 # {'t': ..., 'seq': ..., 'v': ...}

Adapters subclass ``Adapter`` (sinks, processors) or ``RobotAdapter`` (robot
owners) and are registered in the ``sonibus.adapters`` entry-point group.
"""

from .adapter import Adapter
from .busconfig import BusConfig
from .client import robot_info, send_command
from .codec import decode, encode
from .config import Installation, NodeSpec
from .config import load as load_installation
from .errors import AdapterError, CommandError, ConfigError, OwnershipError, RobotNotFound, SonibusError
from .node import Bus
from .owner import RobotAdapter
from .queue import SampleQueue
from .robot import JointSpec, RobotModel, load_model
from .session import open_session
from .verbs import RobotVerbs

__all__ = [
    "Adapter", "AdapterError", "Bus", "BusConfig", "CommandError", "ConfigError", "Installation",
    "JointSpec", "NodeSpec", "OwnershipError", "RobotAdapter", "RobotModel", "RobotNotFound", "RobotVerbs",
    "SampleQueue", "SonibusError", "decode", "encode", "load_installation", "load_model",
    "open_session", "robot_info", "send_command",
]
