"""A ROS 2 robot over rmw_zenoh: its topics are Zenoh keys, so this link is a few
subscriptions and a publisher on a ``Bus`` — the node's own (the robot on the sonibus
network) or one opened to the ROS side's router (``router``).

It shows itself in the ROS graph like a ROS node (``NN``, ``MS`` and ``MP`` liveliness
tokens), attaches rmw_zenoh's sequence number, timestamp and GID to what it publishes,
and checks them on what it receives: a sample without a valid attachment is refused,
as a real rmw_zenoh subscriber drops it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sonibus.bus import codec
from sonibus.bus.busconfig import BusConfig
from sonibus.bus.node import Bus, Qos
from sonibus.bus.queue import SampleQueue
from sonibus.bus.session import open_session

from . import cdr, rmw
from .config import Ros2Config

log = logging.getLogger(__name__)
MAX_PUBLISHERS = 64  # GIDs whose sequence numbers are followed (the table is keyed by what the network sends)
MAX_SUBSCRIPTIONS = 64  # the controller's subscription tokens followed (keyed by what the network sends)
# the type hashes a JointTrajectory subscription may carry without being the controller's own:
# REP-2016's, and Humble-era implementations' placeholder
KNOWN_HASHES = (rmw.HASHES[rmw.JOINT_TRAJECTORY], "TypeHashNotSupported")
COMMANDS = Qos()     # trajectories: reliable, blocking rather than dropped


class RosSession:
    """The ROS side's own Zenoh session, a client of its router (rmw_zenohd), closed with its node."""

    def __init__(self, router: str, bus: Bus) -> None:
        self.session = open_session(BusConfig(mode="client", connect=(router,), multicast=False))
        self.bus = Bus(self.session, bus.node, bus.host, bus.limits)

    def close(self) -> None:
        self.session.close()


class BadInput(ValueError):
    """A sample from the ROS side that is refused; the message says why."""


@dataclass(frozen=True)
class Received:
    """One JointState, with how many messages its publisher's sequence says were lost before it."""

    state: cdr.JointState
    lost: int = 0


class ZenohLink:
    """JointStates in, trajectories out, over rmw_zenoh's wire format."""

    def __init__(self, bus: Bus, config: Ros2Config, on_graph: Callable[[str, bool], None] | None = None) -> None:
        self.bus, self.config = bus, config
        self.on_graph = on_graph
        self.queue = SampleQueue(config.queue)
        self.node = rmw.Node(config.domain_id, bus.zid, config.node_name)
        self._owned: list[Any] = []
        self._last: dict[bytes, int] = {}  # GID → its last sequence number
        self._seq = 0
        self._send_lock = threading.Lock()
        self.trajectory_hash = rmw.HASHES[rmw.JOINT_TRAJECTORY]  # until the controller's subscription says
        self._wanted_hash = self.trajectory_hash
        self.controller_node = controller_node(config.controller)  # (namespace, name) chunks, or None: any node
        self._controller: dict[str, str] = {}  # the controller's subscription tokens alive → their type hash
        self._graph_lock = threading.Lock()

    @property
    def where(self) -> str:
        return (f"rmw_zenoh, domain {self.config.domain_id}, "
                f"{'router ' + self.config.router if self.config.router else 'the sonibus Zenoh network'}")

    def open(self) -> None:
        c = self.config
        self.state_key = rmw.topic_key(c.domain_id, c.joint_states, rmw.JOINT_STATE)
        subscriber, _ = self.bus.subscribe(self.state_key, queue=self.queue, attachment=True)
        self._owned.append(subscriber)
        self._owned.append(self.bus.token(self.node.token()))
        self._owned.append(self.bus.token(self.node.entity(1, "MS", c.joint_states, rmw.JOINT_STATE,
                                                           rmw.HASHES[rmw.JOINT_STATE], rmw.QOS_DEPTH_10)))
        self._publish_as(self.trajectory_hash)
        self._owned.append(self.bus.watch_tokens(f"{rmw.ADMIN}/{c.domain_id}/**", self._graph))

    def _publish_as(self, type_hash: str) -> None:
        """(Re)declare the trajectory publisher and its token with ``type_hash``."""
        c = self.config
        token = self.node.entity(2, "MP", c.controller, rmw.JOINT_TRAJECTORY, type_hash, rmw.QOS_DEPTH_10)
        with self._send_lock:
            for old in (getattr(self, "_publisher", None), getattr(self, "_token", None)):
                if old is not None:
                    old.undeclare()
            self.trajectory_hash = type_hash
            self.gid = rmw.gid(token)
            self.trajectory_key = rmw.topic_key(c.domain_id, c.controller, rmw.JOINT_TRAJECTORY, type_hash)
            self._publisher = self.bus.stream_publisher(self.trajectory_key, COMMANDS, encoding=None)
            self._token = self.bus.token(token)

    def _graph(self, key: str, alive: bool) -> None:
        """A ROS entity came or went: say so, and follow the controller's subscription to its
        topic — matched or not, and the type hash trajectories must carry for it to take them."""
        chunks = key.split("/")
        if len(chunks) < 9 or (chunks[2], chunks[3]) == (self.bus.zid, str(self.node.node_id)):
            return  # (our own node's; another node of this session — ros2-sim's controller in one run — counts)
        if self.on_graph is not None:
            self.on_graph(key, alive)
        if not (len(chunks) >= 13 and chunks[5] == "MS" and chunks[9] == rmw.mangle(self.config.controller)
                and chunks[10] == rmw.JOINT_TRAJECTORY):
            return
        if self.controller_node is not None and (chunks[7], chunks[8]) != self.controller_node:
            return  # another node's subscription on the controller's topic is not the controller
        if self.controller_node is None and chunks[11] not in KNOWN_HASHES:
            return  # without the controller's node to tell, only the type's known hashes are taken
        with self._graph_lock:
            if not alive:
                self._controller.pop(key, None)
            elif key in self._controller or len(self._controller) < MAX_SUBSCRIPTIONS:
                self._controller[key] = chunks[11]
            self._wanted_hash = pick_hash(self.trajectory_hash, list(self._controller.values()))
        # (redeclared by the reader's thread: no declaring in a Zenoh callback)

    def matched(self) -> str:
        """"" while the controller's subscription is alive with the type hash trajectories carry,
        else what is seen instead (for the refusal and the node's description)."""
        with self._graph_lock:
            hashes = sorted(set(self._controller.values()))
        if self.trajectory_hash in hashes:
            return ""
        who = (f"node {self.controller_node[1].replace('%', '')}" if self.controller_node is not None
               else "any node")
        if not hashes:
            return f"no subscription of {who} to {self.config.controller} in the ROS graph ({self.where})"
        return (f"the controller's subscription has type hash {', '.join(h[:20] for h in hashes)}…, "
                f"trajectories {self.trajectory_hash[:20]}…")

    def take(self, timeout: float) -> Received | None:
        """The next JointState (None after ``timeout``); ``BadInput`` for a sample that is refused."""
        wanted = self._wanted_hash
        if wanted != self.trajectory_hash:
            log.info("%s: the controller's subscription on %s has type hash %s: trajectories use it",
                     self.config.robot, self.config.controller, wanted)
            self._publish_as(wanted)
        item = self.queue.get(timeout=timeout)
        if item is None:
            return None
        _key, payload, raw = item
        if isinstance(payload, codec.Oversize):
            raise BadInput(f"a JointState of {payload.size} bytes, over the size limit")
        try:
            attachment = rmw.read_attachment(raw)
            state = cdr.read_joint_state(payload)
        except ValueError as exc:  # a CdrError or a bad attachment
            raise BadInput(str(exc)) from None
        last = self._last.get(attachment.gid)
        if last is None and len(self._last) >= MAX_PUBLISHERS:
            self._last.pop(next(iter(self._last)))
        self._last[attachment.gid] = attachment.sequence
        lost = attachment.sequence - last - 1 if last is not None and attachment.sequence > last + 1 else 0
        return Received(state, lost)

    def send(self, payload: bytes) -> None:
        """Publish one trajectory, attached as rmw_zenoh attaches it."""
        with self._send_lock:
            self._seq += 1
            self._publisher.put(payload, attachment=rmw.attachment(self._seq, time.time_ns(), self.gid))

    def description(self, timeout: float) -> str:
        """The robot's ``/robot_description`` (transient local: asked of the publisher's cache)."""
        c = self.config
        key = rmw.topic_key(c.domain_id, c.description_topic, rmw.STRING)
        limit = self.bus.limits.max_info_payload
        subscriber, queue = self.bus.subscribe(key, maxlen=4, history=True, max_payload=limit)
        token = self.bus.token(self.node.entity(3, "MS", c.description_topic, rmw.STRING, rmw.HASHES[rmw.STRING],
                                                rmw.QOS_TRANSIENT_LOCAL))
        try:
            item = queue.get(timeout=timeout)
        finally:
            subscriber.undeclare()
            token.undeclare()
        if item is None:
            raise BadInput(f"no {c.description_topic} within {timeout:g} s on {key} ({self.where}): is "
                           "robot_state_publisher running? Or give the URDF as a file (key 'urdf')")
        if isinstance(item[1], codec.Oversize):
            raise BadInput(f"{c.description_topic} of {item[1].size} bytes, over {self.bus.limits.max_info_payload}")
        try:
            return cdr.read_string(item[1], self.bus.limits.max_info_payload)
        except cdr.CdrError as exc:
            raise BadInput(f"{c.description_topic}: {exc}") from None

    def close(self) -> None:
        for entity in [*self._owned, getattr(self, "_publisher", None), getattr(self, "_token", None)]:
            if entity is not None:
                try:
                    entity.undeclare()
                except Exception as exc:  # the session closed underneath: nothing left to undeclare
                    log.debug("undeclare at close: %s", exc)
        self._owned.clear()


def controller_node(topic: str) -> tuple[str, str] | None:
    """The (namespace, name) chunks of the node whose ``~/joint_trajectory`` is ``topic``, as its
    liveliness tokens write them: JTC subscribes in its own node's namespace, so
    ``/joint_trajectory_controller/joint_trajectory`` is node ``joint_trajectory_controller`` of
    namespace ``/``. None for a topic of one name (no node to tell): any node's subscription counts."""
    parts = topic.strip("/").split("/")
    if len(parts) < 2:
        return None
    return rmw.mangle("/" + "/".join(parts[:-2]) if parts[:-2] else ""), parts[-2]


def pick_hash(current: str, seen: list[str]) -> str:
    """The type hash trajectories carry, given the controller's subscriptions ``seen``: the current
    one while one of them has it (a hash that works is kept); else a known one they have; else theirs
    (a distro of its own); with none seen, the current one (it worked last)."""
    if current in seen and (current in KNOWN_HASHES or not any(h in KNOWN_HASHES for h in seen)):
        return current
    for candidate in (*KNOWN_HASHES, *sorted(seen)):
        if candidate in seen:
            return candidate
    return current
