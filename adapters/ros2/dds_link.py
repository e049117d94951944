"""A ROS 2 robot over DDS (Fast DDS, Cyclone DDS, Connext: ROS 2's default middlewares),
through Cyclone DDS's Python binding (the ``ros2-dds`` extra). ROS topics are DDS topics
named ``rt/<topic>`` of types ``<package>::msg::dds_::<Type>_``, in XCDR1.

The reader is best effort (it matches reliable and best-effort publishers alike), the
trajectory writer reliable and volatile, keep last 10 (ROS 2's default profile, which a
joint_trajectory_controller subscribes with).
"""

# (no `from __future__ import annotations`: Cyclone reads the IDL structs' annotations as objects)

import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sonibus.bus import registry
from sonibus.bus.queue import SampleQueue

try:
    from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.idl import IdlStruct, types
    from cyclonedds.internal import InvalidSample
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration
except ImportError as exc:
    raise ImportError(f"middleware = \"dds\" needs Cyclone DDS: {registry.install_extra('ros2-dds', 'ros2')} "
                      f"({exc})") from None

from . import cdr
from .config import Ros2Config
from .zenoh_link import BadInput, Received

BATCH = 64  # samples taken at once


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: types.sequence[str]
    position: types.sequence[types.float64]
    velocity: types.sequence[types.float64]
    effort: types.sequence[types.float64]


@dataclass
class Duration(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
class JointTrajectoryPoint(IdlStruct, typename="trajectory_msgs::msg::dds_::JointTrajectoryPoint_"):
    positions: types.sequence[types.float64]
    velocities: types.sequence[types.float64]
    accelerations: types.sequence[types.float64]
    effort: types.sequence[types.float64]
    time_from_start: Duration


@dataclass
class JointTrajectory(IdlStruct, typename="trajectory_msgs::msg::dds_::JointTrajectory_"):
    header: Header
    joint_names: types.sequence[str]
    points: types.sequence[JointTrajectoryPoint]


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


LOOPBACK = ("lo", "lo0", "127.0.0.1", "localhost")
IFF_MULTICAST = 0x1000  # linux/if.h
MAX_PARTICIPANTS = 32  # participant indices probed by unicast discovery: rmw_cyclonedds's localhost mode


def multicast_flag(interface: str) -> str:
    """Cyclone's ``multicast`` attribute for ``interface``: on Linux its own flag, since Cyclone
    presumes multicast on a loopback interface even where the flag is off (it then joins and
    sends SPDP multicast there); "default" (Cyclone's choice) where the flag cannot be read."""
    try:
        flags = int(Path(f"/sys/class/net/{interface}/flags").read_text(), 16)
    except (OSError, ValueError):
        return "default"
    return "true" if flags & IFF_MULTICAST else "false"


def cyclone_xml(config: Ros2Config, user_uri: str = "") -> str:
    """Cyclone's configuration for the installation's ``interface``, ``peers`` and ``multicast``,
    before the user's ``CYCLONEDDS_URI`` (later fragments win; the interface is then the user's).

    Data goes by unicast always (``AllowMulticast spdp``: participants announce themselves by
    multicast where it works, and advertise unicast data locators only), so one configuration
    meets a robot in ROS 2's localhost mode (unicast only) and one discovering by multicast.
    On a loopback interface, 127.0.0.1 is a peer, as ROS 2's own localhost mode has it."""
    general = ""
    if config.interface and not user_uri:
        general = (f'<Interfaces><NetworkInterface name="{config.interface}" '
                   f'multicast="{multicast_flag(config.interface)}"/></Interfaces>')
    general += f"<AllowMulticast>{'spdp' if config.multicast else 'false'}</AllowMulticast>"
    peers = list(config.peers)
    if config.interface in LOOPBACK and "127.0.0.1" not in peers:
        peers.append("127.0.0.1")
    listed = "".join(f'<Peer Address="{p}"/>' for p in peers)
    discovery = (f"<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>{MAX_PARTICIPANTS}"
                 f"</MaxAutoParticipantIndex><Peers>{listed}</Peers>" if peers else "")
    ours = (f'<CycloneDDS><Domain id="any"><General>{general}</General>'
            f"<Discovery>{discovery}</Discovery></Domain></CycloneDDS>")
    return f"{ours},{user_uri}" if user_uri else ours


class DdsLink:
    """JointStates in, trajectories out, over DDS."""

    def __init__(self, config: Ros2Config) -> None:
        self.config = config
        self.queue = SampleQueue(1)  # (only its drop count is read: the reader keeps its own bounded history)
        c = config
        self.user_uri = os.environ.get("CYCLONEDDS_URI", "").strip()
        self.domain = Domain(c.domain_id, cyclone_xml(c, self.user_uri))
        self.participant = DomainParticipant(c.domain_id)
        best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(c.queue))
        self.reader = DataReader(self.participant, Topic(self.participant, "rt/" + c.joint_states.strip("/"),
                                                         JointState), best_effort)
        self.writer = DataWriter(self.participant, Topic(self.participant, "rt/" + c.controller.strip("/"),
                                                         JointTrajectory),
                                 Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                                     Policy.Durability.Volatile, Policy.History.KeepLast(10)))
        self.waitset = WaitSet(self.participant)
        self.waitset.attach(ReadCondition(self.reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        self._pending: list[Any] = []
        self._lock = threading.Lock()

    @property
    def where(self) -> str:
        interface = f", interface {self.config.interface}" if self.config.interface else ""
        if self.user_uri:
            interface += ", CYCLONEDDS_URI"
        return f"DDS domain {self.config.domain_id} (Cyclone DDS{interface})"

    def matched(self) -> str:
        """"" while a subscription matches the trajectory writer (Cyclone's publication-matched
        status), else why not: a command then reaches no controller."""
        if self.writer is None:
            return "closed"
        if self.writer.get_publication_matched_status().current_count:
            return ""
        return f"no subscription matched on rt/{self.config.controller.strip('/')} ({self.where})"

    def silence(self) -> str:
        """Why no JointState arrived (said once, a few seconds after the start)."""
        topic = f"rt/{self.config.joint_states.strip('/')} (domain {self.config.domain_id})"
        if self.reader is not None and self.reader.get_subscription_matched_status().current_count:
            return f"a ROS publisher matched on {topic}, but no data arrived"
        return (f"no ROS publisher matched on {topic}: is the robot on this domain and interface "
                f"({self.where})?")

    def take(self, timeout: float) -> Received | None:
        if not self._pending:
            self.waitset.wait(duration(seconds=timeout))
            taken = self.reader.take(N=BATCH)
            self._pending = [s for s in taken if not isinstance(s, InvalidSample)]  # (not data: a writer gone)
        if not self._pending:
            return None
        sample = self._pending.pop(0)
        try:
            return Received(cdr.JointState(cdr.Stamp(sample.header.stamp.sec, sample.header.stamp.nanosec),
                                           sample.header.frame_id, tuple(sample.name), tuple(sample.position),
                                           tuple(sample.velocity), tuple(sample.effort)))
        except (AttributeError, TypeError) as exc:
            raise BadInput(f"not a JointState: {exc}") from None

    def send(self, payload: bytes) -> None:
        """A trajectory (our CDR, as for rmw_zenoh) written as Cyclone's own type."""
        t = cdr.read_joint_trajectory(payload)
        message = JointTrajectory(Header(Time(t.stamp.sec, t.stamp.nanosec), t.frame_id), list(t.names), [
            JointTrajectoryPoint(list(p.positions), list(p.velocities), [], [],
                                 Duration(cdr.Stamp.of(p.seconds).sec, cdr.Stamp.of(p.seconds).nanosec))
            for p in t.points])
        with self._lock:
            self.writer.write(message)

    def description(self, timeout: float) -> str:
        """The robot's ``/robot_description`` (transient local: DDS keeps it for late readers)."""
        topic = Topic(self.participant, "rt/" + self.config.description_topic.strip("/"), String)
        reader = DataReader(self.participant, topic, Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                                                         Policy.Durability.TransientLocal, Policy.History.KeepLast(1)))
        waitset = WaitSet(self.participant)
        waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        waitset.wait(duration(seconds=timeout))
        samples = reader.take(N=1)
        if not samples:
            raise BadInput(f"no {self.config.description_topic} within {timeout:g} s on {self.where}: is "
                           "robot_state_publisher running? Or give the URDF as a file (key 'urdf')")
        return str(samples[0].data)

    def close(self) -> None:
        """Cyclone deletes its entities once nothing refers to them."""
        for name in ("waitset", "reader", "writer", "participant", "domain"):
            setattr(self, name, None)
        self._pending = []
