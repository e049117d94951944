"""rmw_zenoh's wire format (ros2/rmw_zenoh ``docs/design.md``, checked against its source):
how a ROS 2 topic is a Zenoh key, what each sample's attachment holds, and the
liveliness tokens that make up the ROS graph. Pure functions: no session.

>>> topic_key(0, "/joint_states", JOINT_STATE)
'0/joint_states/sensor_msgs::msg::dds_::JointState_/*'
>>> read_attachment(attachment(7, 1_700_000_000_000_000_000, bytes(range(16)))).sequence
7
>>> mangle("/arm/joint_trajectory"), mangle("")
('%arm%joint_trajectory', '%')
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from sonibus.bus import registry

ADMIN = "@ros2_lv"
JOINT_STATE = "sensor_msgs::msg::dds_::JointState_"
JOINT_TRAJECTORY = "trajectory_msgs::msg::dds_::JointTrajectory_"
STRING = "std_msgs::msg::dds_::String_"
# REP-2016 type hashes (the ones rosbags computes, and Jazzy..Rolling put in keys); Humble-era
# implementations put ``TypeHashNotSupported`` instead, so subscriptions take any (``*``)
HASHES = {
    JOINT_STATE: "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    JOINT_TRAJECTORY: "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e",
    STRING: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
}
GID_SIZE = 16
_ATTACHMENT = struct.Struct("<qqB")
ATTACHMENT_SIZE = _ATTACHMENT.size + GID_SIZE  # 33
# QoS chunks list only what differs from rmw_zenoh's defaults (reliable, volatile, keep last 42):
# <reliability>:<durability>:<history>,<depth>:<deadline s,ns>:<lifespan s,ns>:<liveliness,s,ns>
QOS_DEPTH_10 = "::,10:,:,:,,"            # ROS 2's default profile: reliable, volatile, keep last 10
QOS_TRANSIENT_LOCAL = ":1:,1:,:,:,,"     # /robot_description's: transient local (1), keep last 1


def topic_key(domain: int, topic: str, type_name: str, type_hash: str = "*") -> str:
    """The Zenoh key of ``topic``'s samples in ``domain`` (``*``: whatever type hash the robot's distro puts)."""
    return f"{domain}/{topic.strip('/')}/{type_name}/{type_hash}"


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to every sample: the publisher's sequence number, its source
    timestamp (ns since the epoch) and its GID."""

    sequence: int
    source_ns: int
    gid: bytes


def attachment(sequence: int, source_ns: int, gid: bytes) -> bytes:
    """33 bytes, as zenoh-ext serializes rmw_zenoh's (int64, int64, 16 × uint8): the GID's
    length (16, one LEB128 byte) before it. A real subscriber drops a sample without it."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID is {GID_SIZE} bytes, not {len(gid)}")
    return _ATTACHMENT.pack(sequence, source_ns, GID_SIZE) + gid


def read_attachment(raw: bytes | None) -> Attachment:
    """An attachment back; ``ValueError`` saying what is wrong (missing, short, a GID of another length)."""
    if raw is None:
        raise ValueError("no attachment (rmw_zenoh attaches a sequence number, a timestamp and a GID to "
                         "every sample; a ROS subscriber drops samples without one)")
    if len(raw) != ATTACHMENT_SIZE:
        raise ValueError(f"an attachment of {len(raw)} bytes; rmw_zenoh's are {ATTACHMENT_SIZE}")
    sequence, source_ns, size = _ATTACHMENT.unpack_from(raw)
    if size != GID_SIZE:
        raise ValueError(f"an attachment whose GID is {size} bytes, not {GID_SIZE}")
    return Attachment(sequence, source_ns, bytes(raw[_ATTACHMENT.size:]))


def mangle(name: str) -> str:
    """A name as one chunk of a liveliness key: ``/`` written ``%``, empty as ``%``."""
    return name.replace("/", "%") or "%"


@dataclass(frozen=True)
class Node:
    """A ROS node as rmw_zenoh shows it in the graph: its session's id, a node id, its name."""

    domain: int
    zid: str
    name: str
    namespace: str = ""
    enclave: str = ""
    node_id: int = 0

    def _prefix(self, entity_id: int, kind: str) -> str:
        return "/".join((ADMIN, str(self.domain), self.zid, str(self.node_id), str(entity_id), kind,
                         mangle(self.enclave), mangle(self.namespace), self.name))

    def token(self) -> str:
        """The node's own token (``NN``)."""
        return self._prefix(self.node_id, "NN")

    def entity(self, entity_id: int, kind: str, topic: str, type_name: str, type_hash: str, qos: str) -> str:
        """The token of a publisher (``MP``) or subscription (``MS``) of this node on ``topic``."""
        return "/".join((self._prefix(entity_id, kind), mangle("/" + topic.strip("/")), type_name, type_hash, qos))


def gid(token: str) -> bytes:
    """An entity's GID: the XXH3-128 of its liveliness key, low 64 bits then high (as rmw_zenoh)."""
    try:
        import xxhash
    except ImportError:
        raise ImportError("the ros2 adapter needs xxhash for rmw_zenoh's GIDs: "
                          + registry.install_extra("ros2", "ros2")) from None
    value = xxhash.xxh3_128_intdigest(token.encode())
    return (value & (2**64 - 1)).to_bytes(8, "little") + (value >> 64).to_bytes(8, "little")
